//! Tool-tip trajectories from CSV (`t_s,x_m,y_m,z_m[,jaw]`, a header line
//! allowed), sampled by linear interpolation; errors name the file and line.

use crate::math::V3;
use std::path::Path;
use thiserror::Error;

/// The farthest a trajectory's position may be from the origin on an axis
/// (m): far beyond any haptic device's workspace.
pub const MAX_POSITION_M: f64 = 10.0;

/// A trajectory: strictly increasing times with positions and jaw openings.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    t_s: Vec<f64>,
    p_m: Vec<V3>,
    jaw: Vec<f64>,
}

/// Why a trajectory was refused.
#[derive(Debug, Error)]
pub enum TrajectoryError {
    /// The file could not be read.
    #[error("{file}: {reason}")]
    Io {
        /// The file.
        file: String,
        /// The OS error.
        reason: std::io::Error,
    },
    /// A bad line.
    #[error("{file}:{line}: {message}")]
    Parse {
        /// The file.
        file: String,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// No data.
    #[error("{file}: no samples (expected lines t_s,x_m,y_m,z_m[,jaw])")]
    Empty {
        /// The file.
        file: String,
    },
}

impl Trajectory {
    /// Reads a CSV file.
    pub fn read(path: &Path) -> Result<Self, TrajectoryError> {
        let text = std::fs::read_to_string(path).map_err(|source| TrajectoryError::Io {
            file: path.display().to_string(),
            reason: source,
        })?;
        Self::parse(&path.display().to_string(), &text)
    }

    /// Parses CSV text (`name` is used in messages).
    pub fn parse(name: &str, text: &str) -> Result<Self, TrajectoryError> {
        let mut t = Self {
            t_s: Vec::new(),
            p_m: Vec::new(),
            jaw: Vec::new(),
        };
        // One header line at most: a second line that does not parse is
        // an error at its line (a file of `;`-separated rows was all
        // skipped as headers and reported only as "no samples").
        let mut header_seen = false;
        for (i, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let err = |message: String| TrajectoryError::Parse {
                file: name.to_string(),
                line: i + 1,
                message,
            };
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            if t.t_s.is_empty()
                && !header_seen
                && fields.first().is_some_and(|f| f.parse::<f64>().is_err())
            {
                header_seen = true;
                continue;
            }
            if !(4..=5).contains(&fields.len()) {
                return Err(err(format!(
                    "expected 4 or 5 fields (t_s,x_m,y_m,z_m[,jaw]), found {}",
                    fields.len()
                )));
            }
            let mut v = [0.0; 5];
            for (k, f) in fields.iter().enumerate() {
                v[k] = f
                    .parse::<f64>()
                    .map_err(|_| err(format!("field {} is not a number: {f:?}", k + 1)))?;
                if !v[k].is_finite() {
                    return Err(err(format!("field {} is not finite: {f:?}", k + 1)));
                }
                // A position beyond any device's reach (a column in the
                // wrong unit, say) is refused: it made hapbench report a
                // 300-digit energy.
                if (1..4).contains(&k) && v[k].abs() > MAX_POSITION_M {
                    return Err(err(format!(
                        "field {} ({f}) is more than {MAX_POSITION_M} m from the origin: positions are in metres",
                        k + 1
                    )));
                }
            }
            if let Some(&last) = t.t_s.last()
                && v[0] <= last
            {
                return Err(err(format!(
                    "time {} does not increase (previous {last})",
                    v[0]
                )));
            }
            t.t_s.push(v[0]);
            t.p_m.push([v[1], v[2], v[3]]);
            t.jaw.push(if fields.len() == 5 {
                v[4].clamp(0.0, 1.0)
            } else {
                1.0
            });
        }
        if t.t_s.is_empty() {
            return Err(TrajectoryError::Empty {
                file: name.to_string(),
            });
        }
        Ok(t)
    }

    /// Duration from the first to the last sample (s).
    pub fn duration_s(&self) -> f64 {
        self.t_s[self.t_s.len() - 1] - self.t_s[0]
    }

    /// Position and jaw at `t_s` after the start (held at the ends).
    /// Allocation-free: a binary search and a linear blend.
    pub fn sample(&self, t_s: f64) -> (V3, f64) {
        let t = self.t_s[0] + t_s.max(0.0);
        let k = self.t_s.partition_point(|&x| x <= t);
        if k == 0 {
            return (self.p_m[0], self.jaw[0]);
        }
        if k >= self.t_s.len() {
            let last = self.t_s.len() - 1;
            return (self.p_m[last], self.jaw[last]);
        }
        let (a, b) = (k - 1, k);
        let w = (t - self.t_s[a]) / (self.t_s[b] - self.t_s[a]);
        let p = std::array::from_fn(|d| self.p_m[a][d] + w * (self.p_m[b][d] - self.p_m[a][d]));
        (p, self.jaw[a] + w * (self.jaw[b] - self.jaw[a]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_interpolates_and_names_bad_lines() {
        let t = Trajectory::parse("a.csv", "t_s,x_m,y_m,z_m,jaw\n0,0,0,0,1\n1,1,0,0,0\n").unwrap();
        let (p, jaw) = t.sample(0.25);
        assert_eq!(p, [0.25, 0.0, 0.0]);
        assert!((jaw - 0.75).abs() < 1e-15);
        assert_eq!(t.sample(5.0).0, [1.0, 0.0, 0.0]);
        let e = Trajectory::parse("b.csv", "0,0,0,0\n0,1,0,0\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("b.csv:2:") && e.contains("does not increase"),
            "{e}"
        );
        let e = Trajectory::parse("c.csv", "0,0,0\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("c.csv:1:"), "{e}");
        let e = Trajectory::parse("d.csv", "0,0,0,nan\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("not finite"), "{e}");
        assert!(Trajectory::parse("e.csv", "t_s,x_m,y_m,z_m\n").is_err());
        // One header at most: rows in another separator name their line.
        let e = Trajectory::parse("f.csv", "t_s;x_m;y_m;z_m\n0;0;0;0\n1;0;0;0\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("f.csv:2:") && e.contains("fields"), "{e}");
        let e = Trajectory::parse("g.csv", "0,0,0,0\n1,0,0,1e100\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("g.csv:2:") && e.contains("metres"), "{e}");
    }
}
