//! Turning a table's material keys into a validated [`Material`], with
//! errors placed on the offending value.

use super::ranges::{self, KeyRange};
use super::report::SceneReport;
use super::spec::{MaterialKeys, MaterialModelName, TermName};
use super::{SceneError, SceneSource};
use crate::material::{
    Elasticity, Isotropic, Material, MaterialError, MaterialModel, Terms, TransverselyIsotropic,
};
use std::ops::Range;
use toml::Spanned;

fn value(key: Option<&Spanned<f64>>) -> Option<(f64, Range<usize>)> {
    key.map(|k| (*k.get_ref(), k.span()))
}

/// Each given key within its range ([`ranges`]), warnings in `report`.
fn check_ranges(
    src: &SceneSource,
    keys: &MaterialKeys<'_>,
    what: &str,
    report: &mut SceneReport,
) -> Result<(), SceneError> {
    let checks: [(Option<&Spanned<f64>>, KeyRange); 8] = [
        (keys.young_pa, ranges::YOUNG_PA),
        (keys.poisson, ranges::POISSON),
        (keys.density_kg_m3, ranges::DENSITY_KG_M3),
        (keys.damping_per_s, ranges::DAMPING_PER_S),
        (keys.delta_lambda_pa, ranges::DELTA_LAMBDA_PA),
        (keys.delta_mu_pa, ranges::DELTA_MU_PA),
        (keys.young_fiber_pa, ranges::YOUNG_FIBER_PA),
        (keys.shear_fiber_pa, ranges::SHEAR_FIBER_PA),
    ];
    for (v, range) in checks {
        if let Some(v) = v {
            range.check(src, v, what, report)?;
        }
    }
    Ok(())
}

/// Resolves `keys` into a material. `table` is the span of the table (used
/// when a required key is missing); `anisotropic` says whether the tetrahedra
/// have a fibre, `what` names the table in messages. Each key is within
/// its range ([`ranges`]); values outside the usual one warn in `report`.
pub fn resolve(
    src: &SceneSource,
    keys: &MaterialKeys<'_>,
    anisotropic: bool,
    table: Range<usize>,
    what: &str,
    report: &mut SceneReport,
) -> Result<Material, SceneError> {
    let need = |key: Option<&Spanned<f64>>, name: &str| {
        value(key).ok_or_else(|| src.error(table.clone(), format!("{what}: missing `{name}`")))
    };
    let (young, young_span) = need(keys.young_pa, "young_pa")?;
    let (poisson, poisson_span) = need(keys.poisson, "poisson")?;
    let (density, density_span) = need(keys.density_kg_m3, "density_kg_m3")?;
    let (damping, damping_span) = value(keys.damping_per_s).unwrap_or((0.0, table.clone()));
    // The library's own refusals (a non-finite or non-positive value, an
    // indefinite anisotropy) first, then the plausible ranges.
    let checked = check_ranges(src, keys, what, report);
    let at =
        |span: &Range<usize>, e: MaterialError| src.error(span.clone(), format!("{what}: {e}"));
    let iso = Isotropic::from_young_poisson(young, poisson).map_err(|e| match e {
        MaterialError::Poisson(_) => at(&poisson_span, e),
        _ => at(&young_span, e),
    })?;
    let elasticity = if anisotropic {
        Elasticity::Transverse(transverse(src, keys, iso, table.clone(), what)?)
    } else {
        if keys.any_anisotropic() {
            let span = [
                keys.delta_lambda_pa,
                keys.delta_mu_pa,
                keys.young_fiber_pa,
                keys.shear_fiber_pa,
            ]
            .into_iter()
            .flatten()
            .map(Spanned::span)
            .next()
            .unwrap_or(table);
            return Err(src.error(
                span,
                format!("{what}: anisotropic constants need a `fiber` direction"),
            ));
        }
        Elasticity::Isotropic(iso)
    };
    let model = match keys.model.map(|m| *m.get_ref()) {
        None | Some(MaterialModelName::Linear) => MaterialModel::Linear,
        Some(MaterialModelName::Stvk) => MaterialModel::Stvk,
        Some(MaterialModelName::Corotational) => MaterialModel::Corotational,
    };
    let material = Material::new(elasticity, density, damping)
        .map(|m| m.with_model(model))
        .map_err(|e| match e {
            MaterialError::Damping(_) => at(&damping_span, e),
            _ => at(&density_span, e),
        })?;
    checked.map(|()| material)
}

fn terms_of(keys: &MaterialKeys<'_>) -> Terms {
    match keys.terms {
        None => Terms::ALL,
        Some(list) => Terms {
            stretch: list.get_ref().contains(&TermName::Stretch),
            cross: list.get_ref().contains(&TermName::Cross),
            shear: list.get_ref().contains(&TermName::Shear),
        },
    }
}

fn transverse(
    src: &SceneSource,
    keys: &MaterialKeys<'_>,
    iso: Isotropic,
    table: Range<usize>,
    what: &str,
) -> Result<TransverselyIsotropic, SceneError> {
    let terms = terms_of(keys);
    if let Some(list) = keys.terms
        && list.get_ref().is_empty()
    {
        return Err(src.error(
            list.span(),
            format!("{what}: `terms` must name at least one of stretch, cross, shear"),
        ));
    }
    let paper = keys.delta_lambda_pa.is_some() || keys.delta_mu_pa.is_some();
    let engineering = keys.young_fiber_pa.is_some() || keys.shear_fiber_pa.is_some();
    match (paper, engineering) {
        (true, true) => {
            let span = keys.young_fiber_pa.or(keys.shear_fiber_pa).map(Spanned::span).unwrap_or(table);
            Err(src.error(
                span,
                format!("{what}: give either delta_lambda_pa/delta_mu_pa or young_fiber_pa/shear_fiber_pa, not both"),
            ))
        }
        (true, false) => {
            let (dl, dl_span) = value(keys.delta_lambda_pa).unwrap_or((0.0, table.clone()));
            let (dm, dm_span) = value(keys.delta_mu_pa).unwrap_or((0.0, table.clone()));
            TransverselyIsotropic::new(iso, dl, dm, terms).map_err(|e| {
                let span = if matches!(e, MaterialError::DeltaMu { .. }) { dm_span } else { dl_span };
                src.error(span, format!("{what}: {e}"))
            })
        }
        (false, true) => {
            let (e_l, e_span) = value(keys.young_fiber_pa)
                .ok_or_else(|| src.error(table.clone(), format!("{what}: `shear_fiber_pa` needs `young_fiber_pa`")))?;
            let (g, _) = value(keys.shear_fiber_pa)
                .ok_or_else(|| src.error(table.clone(), format!("{what}: `young_fiber_pa` needs `shear_fiber_pa`")))?;
            if terms != Terms::ALL {
                let span = keys.terms.map(Spanned::span).unwrap_or(table);
                return Err(src.error(span, format!("{what}: engineering constants describe the full material; drop `terms` or use delta_lambda_pa/delta_mu_pa")));
            }
            TransverselyIsotropic::from_engineering(iso, e_l, g).map_err(|e| src.error(e_span, format!("{what}: {e}")))
        }
        (false, false) => Err(src.error(
            table,
            format!("{what}: a fibre needs anisotropic constants: delta_lambda_pa/delta_mu_pa or young_fiber_pa/shear_fiber_pa"),
        )),
    }
}
