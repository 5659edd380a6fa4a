//! The phases of a hand path in contact, tick by tick, so that
//! `hapbench extrapolation` can say where an extrapolator errs: at contact
//! onset, pressing in, sliding, holding, or retracting.

use serde::Serialize;
use std::collections::BTreeMap;

/// Ticks after the force appears that count as contact onset (s).
const ONSET_S: f64 = 0.05;
/// Below this hand speed the hand holds still (m/s).
const STILL_M_S: f64 = 0.001;
/// A zero-force tick with force within this time on both sides is a
/// dropout (s).
const DROPOUT_WINDOW_S: f64 = 0.05;
/// A snap of the truth: its force changing by more than this (N) within
/// [`SNAP_WITHIN_S`], far faster than the hand moves it (on a coarse mesh
/// a probe drags a surface vertex until it slips around it: an elastic
/// instability no sample announces).
const SNAP_JUMP_N: f64 = 0.05;
/// See [`SNAP_JUMP_N`] (s).
const SNAP_WITHIN_S: f64 = 0.005;
/// Ticks from the start of a snap to this long after its end count as near
/// it (s): two periods of a 30 Hz simulation, the time a sample delivered
/// one period late needs to show the new state.
const SNAP_AFTER_S: f64 = 0.067;

/// What the hand does at a tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Phase {
    /// No force.
    Free,
    /// The first 50 ms of a contact.
    Onset,
    /// Moving into the tissue (against the force).
    Press,
    /// Moving along the surface.
    Slide,
    /// Holding still in contact.
    Hold,
    /// Moving out of the tissue (with the force).
    Retract,
}

impl Phase {
    /// The name used in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Free => "free",
            Self::Onset => "onset",
            Self::Press => "press",
            Self::Slide => "slide",
            Self::Hold => "hold",
            Self::Retract => "retract",
        }
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// The phase of each tick, from the truth's force and the hand's motion
/// (`hand` has one more entry than `truth`: the position after the tick).
pub fn classify(truth: &[[f64; 3]], hand: &[[f64; 3]], tick_s: f64) -> Vec<Phase> {
    let onset_ticks = (ONSET_S / tick_s).round() as usize;
    let mut since_contact = usize::MAX;
    truth
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let fm = norm(*f);
            if fm == 0.0 {
                since_contact = usize::MAX;
                return Phase::Free;
            }
            since_contact = if since_contact == usize::MAX {
                0
            } else {
                since_contact + 1
            };
            if since_contact < onset_ticks {
                return Phase::Onset;
            }
            let v: Vec<f64> = (0..3)
                .map(|a| (hand[k + 1][a] - hand[k][a]) / tick_s)
                .collect();
            let speed = norm([v[0], v[1], v[2]]);
            if speed < STILL_M_S {
                return Phase::Hold;
            }
            // The force pushes the hand out of the tissue.
            let vn = (v[0] * f[0] + v[1] * f[1] + v[2] * f[2]) / fm;
            let vt = (speed * speed - vn * vn).max(0.0).sqrt();
            if vt > vn.abs() {
                Phase::Slide
            } else if vn < 0.0 {
                Phase::Press
            } else {
                Phase::Retract
            }
        })
        .collect()
}

/// RMS of `err` per phase (N), for the phases present.
pub fn rms_by_phase(err: &[f64], phases: &[Phase]) -> BTreeMap<&'static str, f64> {
    let mut acc: BTreeMap<&'static str, (f64, usize)> = BTreeMap::new();
    for (e, p) in err.iter().zip(phases) {
        let a = acc.entry(p.name()).or_default();
        a.0 += e * e;
        a.1 += 1;
    }
    acc.into_iter()
        .map(|(k, (s, n))| (k, (s / n.max(1) as f64).sqrt()))
        .collect()
}

/// Per tick, whether it lies within a snap of the truth's force or
/// [`SNAP_AFTER_S`] after one (see [`SNAP_JUMP_N`]).
pub fn near_snaps(truth: &[[f64; 3]], tick_s: f64) -> Vec<bool> {
    let within = (SNAP_WITHIN_S / tick_s).round().max(1.0) as usize;
    let after = (SNAP_AFTER_S / tick_s).round() as usize;
    let mut near = vec![false; truth.len()];
    for k in within..truth.len() {
        let d = [0, 1, 2].map(|i| truth[k][i] - truth[k - within][i]);
        if norm(d) > SNAP_JUMP_N {
            for n in &mut near[k - within..(k + after).min(truth.len())] {
                *n = true;
            }
        }
    }
    near
}

/// RMS of `err` over the ticks not `near` a snap (N), and the share of the
/// squared error in the ticks near one (0 to 1; 0 without error).
pub fn away_from_snaps(err: &[f64], near: &[bool]) -> (f64, f64) {
    let (mut away, mut away_n, mut at) = (0.0, 0usize, 0.0);
    for (e, n) in err.iter().zip(near) {
        if *n {
            at += e * e;
        } else {
            away += e * e;
            away_n += 1;
        }
    }
    let total = away + at;
    (
        (away / away_n.max(1) as f64).sqrt(),
        if total > 0.0 { at / total } else { 0.0 },
    )
}

/// Ticks of exactly zero force with force within 50 ms before and after
/// (the force dropping out while the tool is in the tissue).
pub fn dropouts(force: &[[f64; 3]], tick_s: f64) -> usize {
    let w = (DROPOUT_WINDOW_S / tick_s).round().max(1.0) as usize;
    let touching: Vec<bool> = force.iter().map(|f| norm(*f) > 0.0).collect();
    (0..force.len())
        .filter(|&k| {
            !touching[k]
                && touching[k.saturating_sub(w)..k].iter().any(|t| *t)
                && touching[k + 1..(k + 1 + w).min(force.len())]
                    .iter()
                    .any(|t| *t)
        })
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_press_hold_slide_retract_is_classified_as_such() {
        let h = 0.001;
        // Force up (+z); hand goes down, stays, slides along x, goes up.
        let mut hand = vec![[0.0, 0.0, 0.0]];
        let mut truth = Vec::new();
        let moves = [
            (100, [0.0, 0.0, -0.01]),
            (100, [0.0, 0.0, 0.0]),
            (100, [0.01, 0.0, 0.0]),
            (100, [0.0, 0.0, 0.01]),
        ];
        for (n, v) in moves {
            for _ in 0..n {
                let p = *hand.last().unwrap();
                hand.push([p[0] + v[0] * h, p[1] + v[1] * h, p[2] + v[2] * h]);
                truth.push([0.0, 0.0, 1.0]);
            }
        }
        truth.push([0.0; 3]);
        hand.push(*hand.last().unwrap());
        let p = classify(&truth, &hand, h);
        assert_eq!(p[10], Phase::Onset);
        assert_eq!(p[60], Phase::Press);
        assert_eq!(p[150], Phase::Hold);
        assert_eq!(p[250], Phase::Slide);
        assert_eq!(p[350], Phase::Retract);
        assert_eq!(p[400], Phase::Free);
    }

    #[test]
    fn a_snap_marks_its_window_and_a_steady_ramp_does_not() {
        let h = 0.001;
        // A ramp of 0.5 N/s (0.0025 N per 5 ms), then a 0.2 N drop in 2 ms.
        let mut f: Vec<[f64; 3]> = (0..500).map(|k| [0.0, 0.0, 0.5 * k as f64 * h]).collect();
        let top = f[499][2];
        f.push([0.0, 0.0, top - 0.1]);
        f.extend((0..300).map(|_| [0.0, 0.0, top - 0.2]));
        let near = near_snaps(&f, h);
        assert!(!near[..490].iter().any(|n| *n), "the ramp is no snap");
        assert!(near[500] && near[520] && near[560]);
        assert!(!near[600..].iter().any(|n| *n), "67 ms after it ends");
        // The error is all near the snap: its share is 1, none away.
        let err: Vec<f64> = near.iter().map(|n| if *n { 0.1 } else { 0.0 }).collect();
        assert_eq!(away_from_snaps(&err, &near), (0.0, 1.0));
    }

    #[test]
    fn dropouts_count_gaps_inside_contact_only() {
        let mut f = vec![[0.0, 0.0, 1.0]; 100];
        f[50] = [0.0; 3];
        f[51] = [0.0; 3];
        // Free space before and after is not a dropout.
        let mut all = vec![[0.0; 3]; 200];
        all.extend(f);
        all.extend(vec![[0.0; 3]; 200]);
        assert_eq!(dropouts(&all, 0.001), 2);
    }
}
