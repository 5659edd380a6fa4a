//! Colouring the organ by a field (how far each vertex moved from its rest
//! position), as ParaView, SOFA and iMSTK viewers do: a perceptually
//! uniform map (viridis, van der Walt and Smith 2015: readable in grey and
//! by most colour-blind readers) from the field's range, shown with a
//! colour bar whose ends are that range.
//!
//! The map is a table of viridis's published stops interpolated linearly
//! (eleven stops differ from the full 256-entry table by under 1% of the
//! colour range), so no colour-map crate is needed for one map.

/// What the organ's colour shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ColourBy {
    /// The capsule's colour (cut faces paler).
    #[default]
    Tissue,
    /// |position - rest position| of each vertex, in mm, with a colour bar.
    Displacement,
}

/// viridis at t = 0, 0.1, ..., 1 (sRGB).
const VIRIDIS: [[u8; 3]; 11] = [
    [68, 1, 84],
    [72, 36, 117],
    [65, 68, 135],
    [53, 95, 141],
    [42, 120, 142],
    [33, 145, 140],
    [34, 168, 132],
    [68, 191, 112],
    [122, 209, 81],
    [189, 223, 38],
    [253, 231, 37],
];

/// The map's colour at `t` in [0, 1] (clamped; NaN as 0).
pub fn viridis(t: f32) -> [u8; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (VIRIDIS.len() - 1) as f32;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f32;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    std::array::from_fn(|k| {
        (f32::from(a[k]) + f * (f32::from(b[k]) - f32::from(a[k]))).round() as u8
    })
}

/// Each vertex's displacement from its rest position (mm); vertices the
/// rest shape does not have (none, unless the vertex count changed) are 0.
pub fn displacement_mm(positions_m: &[[f32; 3]], rest_m: &[[f32; 3]]) -> Vec<f32> {
    positions_m
        .iter()
        .enumerate()
        .map(|(i, p)| {
            rest_m.get(i).map_or(0.0, |r| {
                let d = [p[0] - r[0], p[1] - r[1], p[2] - r[2]];
                1e3 * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
            })
        })
        .collect()
}

/// The colour bar's range for a field: 0 to its largest value (a bar that
/// starts at zero reads as "how far", the question a dent asks); a field
/// that is zero everywhere gets [0, 1] so the map is defined.
pub fn range(values: &[f32]) -> [f32; 2] {
    let hi = values
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f32, f32::max);
    [0.0, if hi > 0.0 { hi } else { 1.0 }]
}

/// The vertex colours of `values` over `range`.
pub fn colours(values: &[f32], range: [f32; 2]) -> Vec<[u8; 3]> {
    let span = (range[1] - range[0]).max(f32::MIN_POSITIVE);
    values
        .iter()
        .map(|v| viridis((v - range[0]) / span))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_map_runs_from_dark_violet_to_yellow_and_brightens_monotonically() {
        assert_eq!(viridis(0.0), VIRIDIS[0]);
        assert_eq!(viridis(1.0), VIRIDIS[10]);
        assert_eq!(viridis(-3.0), VIRIDIS[0]);
        assert_eq!(viridis(f32::NAN), VIRIDIS[0]);
        let luma =
            |c: [u8; 3]| 0.3 * f32::from(c[0]) + 0.59 * f32::from(c[1]) + 0.11 * f32::from(c[2]);
        let mut last = -1.0;
        for k in 0..=100 {
            let l = luma(viridis(k as f32 / 100.0));
            assert!(l > last, "luma falls at {k}");
            last = l;
        }
    }

    #[test]
    fn displacement_is_the_distance_from_rest_in_mm_and_the_bar_starts_at_zero() {
        let rest = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let now = [[0.0, 0.0, -0.003], [1.0, 0.004, 0.0], [5.0, 5.0, 5.0]];
        let u = displacement_mm(&now, &rest);
        assert!(
            (u[0] - 3.0).abs() < 1e-4 && (u[1] - 4.0).abs() < 1e-4,
            "{u:?}"
        );
        assert_eq!(u[2], 0.0, "no rest position: no displacement");
        assert_eq!(range(&u), [0.0, u[1]]);
        assert_eq!(range(&[0.0, 0.0]), [0.0, 1.0]);
        let c = colours(&u, range(&u));
        assert_eq!(c[1], VIRIDIS[10]);
        assert_eq!(c[2], VIRIDIS[0]);
    }
}
