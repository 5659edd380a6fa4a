//! The safety filter's configuration and its validation.

use thiserror::Error;

/// Default largest sample age before the force ramps down (50 ms).
pub const DEFAULT_MAX_SAMPLE_AGE_NS: u64 = 50_000_000;
/// Default ramp-down time (10 ms).
pub const DEFAULT_RAMP_DOWN_NS: u64 = 10_000_000;
/// Default ramp-in time (200 ms): slow enough that a hand resting on the
/// handle is not kicked when a simulation (re)starts in contact.
pub const DEFAULT_RAMP_IN_NS: u64 = 200_000_000;
/// The default slew limit lets the force cross its full range (0 to
/// `max_force_n`) in this time (5 ms): faster than the 10 ms ramp-down, so
/// the ramp-down is never slowed by the slew limit, yet a 30 Hz step from
/// the simulation still reaches the hand within a few ticks.
pub const DEFAULT_FULL_SCALE_NS: u64 = 5_000_000;

const NS_PER_S: f64 = 1e9;

/// A configuration the filter cannot honour.
#[derive(Clone, Copy, Debug, Error, PartialEq)]
pub enum SafetyError {
    /// The force limit is not a positive finite number.
    #[error("the force limit must be a positive finite number of newtons, got {0}")]
    MaxForce(f64),
    /// The slew limit is not a positive finite number.
    #[error("the slew limit must be a positive finite number of N/s, got {0}")]
    MaxSlew(f64),
    /// A duration is zero.
    #[error("{0} must be longer than 0 ns")]
    ZeroDuration(&'static str),
    /// The slew limit is too low to ramp the largest force down in time.
    #[error(
        "the slew limit {max_slew_n_per_s} N/s cannot ramp {max_force_n} N down within \
         {ramp_down_ns} ns (needs at least {needed_n_per_s} N/s)"
    )]
    SlewTooLowForRampDown {
        /// The configured slew limit (N/s).
        max_slew_n_per_s: f64,
        /// The force limit (N).
        max_force_n: f64,
        /// The ramp-down time (ns).
        ramp_down_ns: u64,
        /// The smallest slew limit that works (N/s).
        needed_n_per_s: f64,
    },
}

/// The limits the filter enforces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SafetyConfig {
    /// Largest force magnitude sent to the device (N).
    pub max_force_n: f64,
    /// Largest change of the force per second (N/s).
    pub max_slew_n_per_s: f64,
    /// A sample older than this stops the force (ns).
    pub max_sample_age_ns: u64,
    /// Time in which a fault or a shutdown brings the force to zero (ns).
    pub ramp_down_ns: u64,
    /// Time over which the force scale rises from 0 to 1 (ns).
    pub ramp_in_ns: u64,
}

impl SafetyConfig {
    /// `max_force_n` with the defaults for the rest: sample age 50 ms,
    /// ramp-down 10 ms, ramp-in 200 ms, and a slew limit of
    /// `max_force_n / 5 ms`. Validated.
    pub fn new(max_force_n: f64) -> Result<Self, SafetyError> {
        let cfg = Self {
            max_force_n,
            max_slew_n_per_s: max_force_n * (NS_PER_S / DEFAULT_FULL_SCALE_NS as f64),
            max_sample_age_ns: DEFAULT_MAX_SAMPLE_AGE_NS,
            ramp_down_ns: DEFAULT_RAMP_DOWN_NS,
            ramp_in_ns: DEFAULT_RAMP_IN_NS,
        };
        cfg.validate()?;
        Ok(cfg)
    }

    /// Checks that the limits are positive and finite, the durations
    /// non-zero, and that the slew limit allows a linear ramp from the
    /// largest force to zero within `ramp_down_ns` (otherwise the two
    /// promises contradict each other).
    pub fn validate(&self) -> Result<(), SafetyError> {
        if !(self.max_force_n.is_finite() && self.max_force_n > 0.0) {
            return Err(SafetyError::MaxForce(self.max_force_n));
        }
        if !(self.max_slew_n_per_s.is_finite() && self.max_slew_n_per_s > 0.0) {
            return Err(SafetyError::MaxSlew(self.max_slew_n_per_s));
        }
        for (value, name) in [
            (self.max_sample_age_ns, "max_sample_age_ns"),
            (self.ramp_down_ns, "ramp_down_ns"),
            (self.ramp_in_ns, "ramp_in_ns"),
        ] {
            if value == 0 {
                return Err(SafetyError::ZeroDuration(name));
            }
        }
        let needed = self.max_force_n / (self.ramp_down_ns as f64 / NS_PER_S);
        if self.max_slew_n_per_s < needed {
            return Err(SafetyError::SlewTooLowForRampDown {
                max_slew_n_per_s: self.max_slew_n_per_s,
                max_force_n: self.max_force_n,
                ramp_down_ns: self.ramp_down_ns,
                needed_n_per_s: needed,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults() {
        let c = SafetyConfig::new(8.0).unwrap();
        assert_eq!(c.max_force_n, 8.0);
        assert_eq!(c.max_slew_n_per_s, 1600.0);
        assert_eq!(c.max_sample_age_ns, 50_000_000);
        assert_eq!(c.ramp_down_ns, 10_000_000);
        assert_eq!(c.ramp_in_ns, 200_000_000);
    }

    #[test]
    fn rejects_bad_force_limits() {
        for f in [0.0, -1.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(
                matches!(SafetyConfig::new(f), Err(SafetyError::MaxForce(_))),
                "{f}"
            );
        }
        // The default slew limit of an absurd force limit overflows.
        assert!(matches!(
            SafetyConfig::new(f64::MAX),
            Err(SafetyError::MaxSlew(_))
        ));
    }

    #[test]
    fn rejects_bad_slew_and_durations() {
        let good = SafetyConfig::new(8.0).unwrap();
        for s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let c = SafetyConfig {
                max_slew_n_per_s: s,
                ..good
            };
            assert!(matches!(c.validate(), Err(SafetyError::MaxSlew(_))), "{s}");
        }
        let c = SafetyConfig {
            ramp_down_ns: 0,
            ..good
        };
        assert_eq!(c.validate(), Err(SafetyError::ZeroDuration("ramp_down_ns")));
        let c = SafetyConfig {
            ramp_in_ns: 0,
            ..good
        };
        assert_eq!(c.validate(), Err(SafetyError::ZeroDuration("ramp_in_ns")));
        let c = SafetyConfig {
            max_sample_age_ns: 0,
            ..good
        };
        assert_eq!(
            c.validate(),
            Err(SafetyError::ZeroDuration("max_sample_age_ns"))
        );
    }

    #[test]
    fn slew_must_allow_the_ramp_down() {
        let good = SafetyConfig::new(8.0).unwrap();
        // 8 N in 10 ms needs 800 N/s.
        let c = SafetyConfig {
            max_slew_n_per_s: 800.0,
            ..good
        };
        assert_eq!(c.validate(), Ok(()));
        let c = SafetyConfig {
            max_slew_n_per_s: 799.0,
            ..good
        };
        let e = c.validate().unwrap_err();
        assert!(
            matches!(e, SafetyError::SlewTooLowForRampDown { needed_n_per_s, .. } if needed_n_per_s == 800.0)
        );
        assert!(e.to_string().contains("800"), "{e}");
    }
}
