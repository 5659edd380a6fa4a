//! The nonlinear pass's lanes (four f64, eight f32) against the scalar path.

use super::super::kernel::Kernel;
use super::super::lanes::LaneBlock;
use super::lane_set::block;
use super::*;
use crate::material::{Elasticity, Isotropic, Material, Terms, TransverselyIsotropic};
use crate::material_map::TetMaterials;
use crate::mesh::{BoxSpec, CellSize};

/// A 2 x 1 x 1 cm block of `model` elements, a third of them
/// anisotropic (fibres along (1, 0.3, 0.2)), tetrahedron 6 removed.
fn mixed_block(model: MaterialModel) -> ElasticModel {
    let mesh = BoxSpec::new(Vec3::new(0.02, 0.01, 0.01), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let iso = Isotropic::from_young_poisson(4500.0, 0.4).unwrap();
    let aniso = TransverselyIsotropic::new(iso, 3000.0, 2500.0, Terms::ALL).unwrap();
    let material = |e| Material::new(e, 1000.0, 0.0).unwrap().with_model(model);
    let mut mats = TetMaterials::uniform(material(Elasticity::Isotropic(iso)), mesh.tet_count());
    let id = mats.add(material(Elasticity::Transverse(aniso))).unwrap();
    for t in (0..mesh.tet_count()).filter(|t| t % 3 == 1) {
        mats.assign(TetId::from(t), id).unwrap();
        mats.set_fiber(TetId::from(t), Vec3::new(1.0, 0.3, 0.2))
            .unwrap();
    }
    let mut model = ElasticModel::new(mesh, mats).unwrap();
    model.remove_tet(TetId(6)).unwrap();
    model
}

/// How many blocks of `large` are StVK lanes, corotational lanes and
/// scalar, and the lane count.
fn block_kinds(large: &LargeStrain) -> ([usize; 3], usize) {
    fn kinds<S: Scalar, const N: usize>(set: &LaneSet<S, N>) -> ([usize; 3], usize) {
        let mut k = [0; 3];
        for b in &set.blocks {
            k[match b {
                Block::Stvk(_) => 0,
                Block::Corotational(_) => 1,
                Block::Scalar => 2,
            }] += 1;
        }
        (k, N)
    }
    match &large.lanes {
        Lanes::F64(set) => kinds(set),
        Lanes::F32(set) => kinds(set),
    }
}

/// How close the lanes must be to the scalar path: f64 lanes to
/// round-off; f32 lanes to f32's precision of the element's forces
/// (relative to the linear force plus the correction: a small
/// correction is a difference of larger terms).
struct Tolerance {
    /// Of the largest element force.
    force: Real,
    /// Of 1 in |q . q'|.
    rotation: Real,
    /// Of the bound.
    lambda: Real,
}

fn tolerance(precision: LanePrecision) -> Tolerance {
    match precision {
        LanePrecision::F64 => Tolerance {
            force: 1e-12,
            rotation: 1e-12,
            lambda: 1e-9,
        },
        LanePrecision::F32 => Tolerance {
            force: 1e-6,
            rotation: 1e-6,
            lambda: 1e-5,
        },
    }
}

/// The largest element force of the linear model at `u` plus that of
/// the scalar path's corrections `scalar` (per element): the scale the
/// f32 lanes are judged against (taken from the reference, not from what
/// is checked).
fn force_scale(large: &LargeStrain, u: &[V3], scalar: &[[V3; 4]]) -> Real {
    let mut scale: Real = 0.0;
    for (e, corrections) in large.elements.iter().zip(scalar) {
        let du = e.vertices.map(|v| Vec3::from_array(u[v as usize]));
        let f = deformation_gradient(&e.geom, &du);
        let mut unused = DQuat::IDENTITY;
        let lin = first_piola(Law::Linear, &e.elastic, &f, &mut unused);
        for m in &e.geom.shape {
            scale = scale.max((lin * *m).abs().max_element() * e.geom.volume_m3);
        }
        scale = scale.max(
            corrections
                .iter()
                .flatten()
                .fold(0.0, |m, x| m.max(x.abs())),
        );
    }
    scale
}

/// The scalar path's element forces at `u` from rotations `before` (zero
/// for removed elements).
fn scalar_forces(large: &LargeStrain, u: &[V3], before: &[DQuat]) -> Vec<[V3; 4]> {
    (0..large.len())
        .map(|i| {
            let mut f = [[0.0; 3]; 4];
            if large.alive[i] {
                let mut q = before[i];
                element(&large.elements[i], &mut q, &mut f, u, false);
            }
            f
        })
        .collect()
}

/// A 2.4 x 1.2 x 1.2 cm block of 324 tetrahedra (not a multiple of eight)
/// with StVK and corotational elements, so that the lanes hold blocks of
/// each model, a block of both (scalar) and a short last block (scalar).
fn two_model_block() -> ElasticModel {
    let mesh = BoxSpec::new(Vec3::new(0.024, 0.012, 0.012), CellSize::EdgeM(0.004))
        .generate()
        .unwrap();
    assert_eq!(mesh.tet_count() % 8, 4);
    let iso = Isotropic::from_young_poisson(4500.0, 0.4).unwrap();
    let material = |m| {
        Material::new(Elasticity::Isotropic(iso), 1000.0, 0.0)
            .unwrap()
            .with_model(m)
    };
    let mut mats = TetMaterials::uniform(material(MaterialModel::Stvk), mesh.tet_count());
    let id = mats.add(material(MaterialModel::Corotational)).unwrap();
    for t in (0..mesh.tet_count()).filter(|t| t % 5 == 2) {
        mats.assign(TetId::from(t), id).unwrap();
    }
    ElasticModel::new(mesh, mats).unwrap()
}

/// The vertex sums of a pass equal the scalar path's element forces
/// summed per vertex (both precisions), the same to the bit in one task
/// or split into many, and follow an element's removal and restoration.
#[test]
fn vertex_sums_equal_the_scalar_forces_summed() {
    for precision in [LanePrecision::F64, LanePrecision::F32] {
        let model = two_model_block();
        let mut large = LargeStrain::with_precision(&model, precision).unwrap();
        let scalar_blocks = block_kinds(&large).0[2];
        // A mixed block; in eights also a short last one (324 = 40 x 8 + 4).
        let expected = if precision == LanePrecision::F32 {
            2
        } else {
            1
        };
        assert!(scalar_blocks >= expected, "{precision:?}: {scalar_blocks}");
        let p = model.mesh().positions_m();
        let u: Vec<V3> = p
            .iter()
            .map(|x| {
                let t = 12.0 * x.x;
                [0.3 * x.z * t, -0.1 * x.y + 0.2 * x.x * t, -0.25 * x.y * t]
            })
            .collect();
        // An element inside a corotational lane block, removed after a pass.
        let removed = (0..large.len() - 16)
            .find(|i| {
                large.elements[*i..*i + 16]
                    .iter()
                    .all(|e| e.model == MaterialModel::Corotational)
            })
            .map(|i| i + 8)
            .unwrap();
        let tet = TetId::from(
            large
                .element_of
                .iter()
                .position(|e| *e as usize == removed)
                .unwrap(),
        );
        for step in 0..3 {
            if step == 1 {
                large.set_alive(tet, false);
            } else if step == 2 {
                large.set_alive(tet, true);
            }
            if step > 0 {
                // Its lane's rotation starts afresh (a dead lane with H = 0
                // and another rotation would push).
                assert_eq!(large.rotation(removed), DQuat::IDENTITY, "{precision:?}");
            }
            let before = large.rotations();
            let mut split = large.clone();
            let mut out = vec![[0.0; 3]; u.len()];
            let mut out_split = vec![[0.0; 3]; u.len()];
            large.pass_in_tasks(&u, &mut out, usize::MAX);
            split.pass_in_tasks(&u, &mut out_split, 16);
            assert_eq!(out, out_split, "{precision:?}: one task against many");
            let forces = scalar_forces(&large, &u, &before);
            let mut sums = vec![[0.0; 3]; u.len()];
            for (e, f) in large.elements.iter().zip(&forces) {
                for (v, fk) in e.vertices.iter().zip(f) {
                    for d in 0..3 {
                        sums[*v as usize][d] += fk[d];
                    }
                }
            }
            let scale = force_scale(&large, &u, &forces);
            let tol = match precision {
                LanePrecision::F64 => 1e-10 * scale,
                LanePrecision::F32 => 1e-5 * scale,
            };
            for (v, (a, b)) in sums.iter().zip(&out).enumerate() {
                for d in 0..3 {
                    assert!(
                        (a[d] - b[d]).abs() <= tol,
                        "{precision:?} step {step} vertex {v}: {a:?} vs {b:?}"
                    );
                }
            }
            let zero = split
                .element_forces(removed)
                .iter()
                .flatten()
                .all(|x| *x == 0.0);
            assert_eq!(zero, step == 1, "{precision:?} step {step}");
        }
    }
}

/// The StVK lane blocks (four f64 or eight f32) give the scalar path's
/// forces and bound: isotropic and anisotropic lanes, a removed element,
/// stretched and squeezed (barrier) states.
#[test]
fn lanes_equal_the_scalar_path() {
    stvk_lanes_equal_the_scalar_path(LanePrecision::F64);
    stvk_lanes_equal_the_scalar_path(LanePrecision::F32);
}

fn stvk_lanes_equal_the_scalar_path(precision: LanePrecision) {
    let tol = tolerance(precision);
    let model = mixed_block(MaterialModel::Stvk);
    let mut large = LargeStrain::with_precision(&model, precision).unwrap();
    let stvk_blocks = block_kinds(&large).0[0];
    assert!(stvk_blocks > 0);
    let p = model.mesh().positions_m();
    for squash in [1.0, 0.3] {
        let u: Vec<V3> = p
            .iter()
            .map(|x| {
                [
                    0.4 * x.x + 0.1 * x.z,
                    (squash - 1.0) * x.y,
                    -0.2 * x.x * x.y / 0.01,
                ]
            })
            .collect();
        let mut out = vec![[0.0; 3]; u.len()];
        large.pass_keeping_element_forces(&u, &mut out);
        let reference = scalar_forces(&large, &u, &large.rotations());
        let scale = force_scale(&large, &u, &reference);
        let mut lambda: Real = 0.0;
        let mut collapsed = 0;
        for (i, e) in large.elements.iter().enumerate() {
            let mut f = [[0.0; 3]; 4];
            if large.alive[i] {
                let r = element(e, &mut DQuat::default(), &mut f, &u, false);
                lambda = lambda.max(r.lambda);
                collapsed += r.collapsed;
            }
            for (a, b) in f.iter().zip(&large.element_forces(i)) {
                for d in 0..3 {
                    let bound = match precision {
                        LanePrecision::F64 => tol.force * (1.0 + a[d].abs()),
                        LanePrecision::F32 => tol.force * scale,
                    };
                    assert!(
                        (a[d] - b[d]).abs() <= bound,
                        "{precision:?} element {i}: {a:?} vs {b:?}"
                    );
                }
            }
        }
        assert!((large.last().lambda - lambda).abs() <= tol.lambda * lambda);
        assert_eq!(large.last().collapsed, collapsed);
        assert_eq!(collapsed > 0, squash < 0.5, "squash {squash}");
    }
}

/// The corotational lane blocks (four f64 or eight f32) give the
/// scalar path's forces, rotations and bound, warm-started from the
/// rotations the previous pass left: isotropic and anisotropic lanes, a
/// removed element, a small deformation, a large rotation (many
/// iterations) and an inverted state (Mueller's steps).
#[test]
fn corotational_lanes_equal_the_scalar_path() {
    corotational_lanes_equal(LanePrecision::F64);
    corotational_lanes_equal(LanePrecision::F32);
}

fn corotational_lanes_equal(precision: LanePrecision) {
    let tol = tolerance(precision);
    // The rotation converges to 1e-6 rad, its error about the square.
    let corotational_force_tol = match precision {
        LanePrecision::F64 => 1e-10,
        LanePrecision::F32 => tol.force,
    };
    let model = mixed_block(MaterialModel::Corotational);
    let mut large = LargeStrain::with_precision(&model, precision).unwrap();
    let ([_, lanes, _], width) = block_kinds(&large);
    assert_eq!(lanes, large.elements.len() / width);
    let p = model.mesh().positions_m();
    let turned = |angle: Real, shear: Real, flip: Real| -> Vec<V3> {
        let r = Mat3::from_rotation_z(angle) * Mat3::from_rotation_x(0.5 * angle);
        p.iter()
            .map(|x| {
                let y = Vec3::new(x.x + shear * x.y / 0.01 * 0.002, x.y, flip * x.z);
                (r * y - *x).to_array()
            })
            .collect()
    };
    for u in [
        turned(0.01, 0.1, 1.0),
        turned(0.02, 0.12, 1.0),
        turned(1.3, 0.3, 1.0),
        turned(0.4, 0.2, -0.3),
    ] {
        let before = large.rotations();
        let mut out = vec![[0.0; 3]; u.len()];
        large.pass_keeping_element_forces(&u, &mut out);
        let mut lambda: Real = 0.0;
        let scale = match precision {
            LanePrecision::F64 => (0..large.len())
                .flat_map(|i| large.element_forces(i))
                .flatten()
                .fold(0.0 as Real, |m, x| m.max(x.abs())),
            LanePrecision::F32 => force_scale(&large, &u, &scalar_forces(&large, &u, &before)),
        };
        for (i, e) in large.elements.iter().enumerate() {
            let mut f = [[0.0; 3]; 4];
            let mut q = before[i];
            if large.alive[i] {
                lambda = lambda.max(element(e, &mut q, &mut f, &u, false).lambda);
            }
            assert!(
                (q.dot(large.rotation(i)).abs() - 1.0).abs() < tol.rotation,
                "{precision:?} element {i}: rotation {q:?} vs {:?}",
                large.rotation(i)
            );
            for (a, b) in f.iter().zip(&large.element_forces(i)) {
                for d in 0..3 {
                    assert!(
                        (a[d] - b[d]).abs() <= corotational_force_tol * scale,
                        "{precision:?} element {i}: {a:?} vs {b:?} (scale {scale}, q {q:?} vs {:?})",
                        large.rotation(i)
                    );
                }
            }
        }
        assert!((large.last().lambda - lambda).abs() <= tol.lambda * lambda);
    }
}

/// The lanes' stress of a symmetric strain equals the scalar
/// `TetElastic::stress` of each lane (isotropic and anisotropic lanes), in
/// f64 to round-off and in f32 to its precision, and is symmetric.
#[test]
fn lane_stress_equals_the_scalar_stress() {
    let model = mixed_block(MaterialModel::Stvk);
    let large = LargeStrain::new(&model).unwrap();
    let e = Mat3::from_cols_array(&[
        0.012, -0.004, 0.007, -0.004, -0.009, 0.002, 0.007, 0.002, 0.015,
    ]);
    for chunk in large.elements.chunks_exact(8).take(3) {
        let wide: LaneBlock<f64, 8> = block(chunk);
        let narrow: LaneBlock<f32, 8> = block(chunk);
        let lane64: [[[f64; 8]; 3]; 3] =
            std::array::from_fn(|r| std::array::from_fn(|c| [e.col(c)[r]; 8]));
        let lane32: [[[f32; 8]; 3]; 3] =
            std::array::from_fn(|r| std::array::from_fn(|c| [e.col(c)[r] as f32; 8]));
        let s64 = super::super::lanes::stress(&wide, &lane64);
        let s32 = super::super::lanes::stress(&narrow, &lane32);
        for (l, el) in chunk.iter().enumerate() {
            let reference = el.elastic.stress(&e);
            let size = (0..3)
                .map(|c| reference.col(c).abs().max_element())
                .fold(0.0, Real::max);
            for r in 0..3 {
                for c in 0..3 {
                    let want = reference.col(c)[r];
                    assert!(
                        (s64[r][c][l] - want).abs() <= 1e-12 * size,
                        "{r}{c} lane {l}"
                    );
                    assert!(
                        (s32[r][c][l] as Real - want).abs() <= 1e-6 * size,
                        "{r}{c} lane {l}"
                    );
                    assert_eq!(s64[r][c][l], s64[c][r][l]);
                }
            }
        }
    }
}

/// Element `i`'s linear forces at `u`, -V sigma(sym H) m_k (f64).
fn linear_forces(e: &Element, u: &[V3]) -> [V3; 4] {
    let du = e.vertices.map(|v| Vec3::from_array(u[v as usize]));
    let f = deformation_gradient(&e.geom, &du);
    let lin = first_piola(Law::Linear, &e.elastic, &f, &mut DQuat::default()) * (-e.geom.volume_m3);
    e.geom.shape.map(|m| (lin * m).to_array())
}

/// The whole-force pass (every tetrahedron nonlinear, beside a kernel
/// without tensors) gives each element's correction plus its linear
/// force, in both precisions and both models, and a removed element
/// nothing; a model with a linear tetrahedron is not covered.
#[test]
fn whole_forces_are_the_corrections_plus_the_linear_forces() {
    for precision in [LanePrecision::F64, LanePrecision::F32] {
        for law in [MaterialModel::Stvk, MaterialModel::Corotational] {
            let model = mixed_block(law);
            let mut corrections = LargeStrain::with_precision(&model, precision).unwrap();
            assert!(corrections.covers_every_tetrahedron());
            let mut whole = corrections.clone().computing_whole_forces();
            let p = model.mesh().positions_m();
            let u: Vec<V3> = p
                .iter()
                .map(|x| [0.3 * x.y + 0.05 * x.z, -0.2 * x.x, 0.15 * x.x * x.y / 0.01])
                .collect();
            let mut out = vec![[0.0; 3]; u.len()];
            corrections.pass_keeping_element_forces(&u, &mut out);
            whole.pass_keeping_element_forces(&u, &mut out);
            let lin: Vec<[V3; 4]> = whole
                .elements
                .iter()
                .map(|e| linear_forces(e, &u))
                .collect();
            let scale = force_scale(&whole, &u, &lin);
            let tol = match precision {
                LanePrecision::F64 => 1e-10 * scale,
                LanePrecision::F32 => 1e-5 * scale,
            };
            for (i, l) in lin.iter().enumerate() {
                let (c, w) = (corrections.element_forces(i), whole.element_forces(i));
                for k in 0..4 {
                    for d in 0..3 {
                        let want = if whole.alive[i] {
                            c[k][d] + l[k][d]
                        } else {
                            0.0
                        };
                        assert!(
                            (w[k][d] - want).abs() <= tol,
                            "{precision:?} {law:?} element {i}: {w:?} vs {c:?} + {l:?}"
                        );
                    }
                }
            }
        }
    }
    let model = ElasticModel::new(
        BoxSpec::new(Vec3::new(0.02, 0.01, 0.01), CellSize::EdgeM(0.005))
            .generate()
            .unwrap(),
        {
            let iso = Isotropic::from_young_poisson(4500.0, 0.4).unwrap();
            let m = |law| {
                Material::new(Elasticity::Isotropic(iso), 1000.0, 0.0)
                    .unwrap()
                    .with_model(law)
            };
            let mut mats = TetMaterials::uniform(m(MaterialModel::Stvk), 96);
            let linear = mats.add(m(MaterialModel::Linear)).unwrap();
            mats.assign(TetId(5), linear).unwrap();
            mats
        },
    )
    .unwrap();
    assert!(!LargeStrain::new(&model).unwrap().covers_every_tetrahedron());
    // The explicit step keeps the linear tensors only where some element
    // needs them.
    let config = || super::super::ExplicitConfig::new(1e-5);
    let mixed = super::super::Explicit::<f32>::new(model, config()).unwrap();
    assert!(mixed.kernel().is_elastic());
    let all =
        super::super::Explicit::<f32>::new(mixed_block(MaterialModel::Stvk), config()).unwrap();
    assert!(!all.kernel().is_elastic());
    // With a linear capsule membrane the kernel holds its springs alone.
    let capsule = mixed_block(MaterialModel::Stvk)
        .with_membrane(5000.0, crate::membrane::MembraneModel::Linear)
        .unwrap();
    let with_capsule = super::super::Explicit::<f32>::new(capsule, config()).unwrap();
    assert!(!with_capsule.kernel().is_elastic());
    assert!(with_capsule.kernel().blocks() > 0);
    assert!(with_capsule.kernel().blocks() < mixed.kernel().blocks());
}

/// An all-StVK block stepped with whole forces beside a kernel without the
/// elements' tensors follows the same trajectory as with the linear copy
/// and corrections, through a cut of a capsule element and its
/// restoration, on two threads, in f64 and f32; with a linear capsule
/// membrane (whose springs the kernel then holds alone) and without. The
/// capsule's force the kernel reports at each vertex (part of a held
/// tool's reaction) is -(K U) of the model's tensors with the capsule less
/// those without it.
#[test]
fn whole_forces_step_as_the_corrections_do() {
    fn run<S: super::super::Storage>(capsule: bool, whole: bool) -> Vec<V3> {
        let mut model = mixed_block(MaterialModel::Stvk);
        if capsule {
            model = model
                .with_membrane(5000.0, crate::membrane::MembraneModel::Linear)
                .unwrap();
        }
        let mut config = super::super::ExplicitConfig::new(2e-4);
        config.threads = 2;
        let mut sim = if whole {
            super::super::Explicit::<S>::new(model, config).unwrap()
        } else {
            super::super::Explicit::<S>::with_linear_tensors(model, config).unwrap()
        };
        assert_eq!(sim.kernel().is_elastic(), !whole);
        let p = sim.model().mesh().positions_m().to_vec();
        for (v, x) in p.iter().enumerate() {
            let id = crate::ids::VertexId(v as u32);
            if x.x < 1e-9 {
                sim.fix(id);
            } else if x.x > 0.02 - 1e-9 {
                sim.prescribe(id, Vec3::new(0.004, -0.003, 0.002));
            }
        }
        let faces = |sim: &super::super::Explicit<S>| {
            let m = sim.model();
            m.membrane().map_or(0, |c| c.face_count(m.topology()))
        };
        for step in 0..120 {
            if step == 40 {
                let before = faces(&sim);
                sim.remove_tet(TetId(20)).unwrap();
                assert!(
                    !capsule || faces(&sim) < before,
                    "the cut takes capsule faces"
                );
            }
            if step == 80 {
                sim.restore_tet(TetId(20)).unwrap();
            }
            if step == 100 && capsule && whole {
                check_capsule_force(&sim, S::LANES == LanePrecision::F32);
            }
            sim.step();
        }
        sim.displacements().to_vec()
    }
    for capsule in [false, true] {
        for (a, b, tol) in [
            (run::<f64>(capsule, false), run::<f64>(capsule, true), 1e-9),
            (run::<f32>(capsule, false), run::<f32>(capsule, true), 1e-4),
        ] {
            let scale = b.iter().flatten().fold(0.0 as Real, |m, x| m.max(x.abs()));
            assert!(scale > 1e-3, "the block deforms: {scale}");
            for (x, y) in a.iter().zip(&b) {
                for d in 0..3 {
                    assert!((x[d] - y[d]).abs() <= tol * scale, "{x:?} vs {y:?}");
                }
            }
        }
    }
}

/// The capsule's force at every vertex as the whole-force kernel reports
/// it against -(K U) with the capsule less without it (the block restored
/// after its cut, so a fresh block's tensors are the elements' own).
fn check_capsule_force<S: super::super::Storage>(sim: &super::super::Explicit<S>, f32: bool) {
    let u = sim.displacements();
    let mut with = vec![[0.0; 3]; u.len()];
    Kernel::<f64>::new(sim.model()).apply(u, &mut with);
    let mut without = vec![[0.0; 3]; u.len()];
    Kernel::<f64>::new(&mixed_block(MaterialModel::Stvk)).apply(u, &mut without);
    let expected: Vec<Vec3> = (with.iter().zip(&without))
        .map(|(a, b)| Vec3::from_array(*b) - Vec3::from_array(*a))
        .collect();
    let scale = expected
        .iter()
        .fold(0.0 as Real, |m, f| m.max(f.abs().max_element()));
    assert!(scale > 1e-4, "the capsule pulls: {scale} N");
    let tol = if f32 { 1e-6 } else { 1e-12 };
    for (v, e) in expected.iter().enumerate() {
        let got = sim
            .kernel()
            .capsule_force_n(crate::ids::VertexId(v as u32), u);
        let got = Vec3::from_array(got.expect("the kernel holds the capsule alone"));
        assert!(
            (got - *e).abs().max_element() <= tol * scale,
            "vertex {v}: {got} vs {e}"
        );
    }
}

/// The AVX2 data movement of eight f32 lanes (corner differences into
/// lanes, the lanes' forces summed at the vertices) equals the portable
/// one to the bit: over a translated body (differences of large
/// displacements), a removed lane, differences below the flush floor and
/// a NaN displacement.
#[cfg(target_arch = "x86_64")]
#[test]
fn avx2_data_movement_equals_the_portable_one_to_the_bit() {
    if !std::arch::is_x86_feature_detected!("avx2") {
        eprintln!("no AVX2 on this CPU: the portable form is the only one");
        return;
    }
    use super::super::lanes::{corner_differences, portable_corner_differences};
    let model = mixed_block(MaterialModel::Stvk);
    let mut large = LargeStrain::with_precision(&model, LanePrecision::F32).unwrap();
    let p = model.mesh().positions_m();
    let mut u: Vec<V3> = p
        .iter()
        .enumerate()
        .map(|(i, x)| {
            [
                0.1 + 0.03 * x.x - 0.2 * x.y * x.z / 0.01,
                -0.05 + (i % 3) as Real * 1e-13,
                0.02 * x.z + 1e-4 * (i % 7) as Real,
            ]
        })
        .collect();
    u[5][1] = Real::NAN;
    // NaN payloads are not compared (LLVM may swap an add's operands).
    let bits = |du: &[[[f32; 8]; 3]; 3]| {
        du.map(|k| k.map(|c| c.map(|x| if x.is_nan() { u32::MAX } else { x.to_bits() })))
    };
    let Lanes::F32(set) = &large.lanes else {
        panic!("f32 lanes")
    };
    let mut compared = 0;
    for (k, block) in set.blocks.iter().enumerate() {
        let Block::Stvk(b) = block else { continue };
        for pattern in [
            [true; 8],
            [true, false, true, true, false, true, true, true],
        ] {
            let alive: [bool; 8] = std::array::from_fn(|l| pattern[l] && large.alive[k * 8 + l]);
            let fast = corner_differences(b, alive, &u);
            let portable = portable_corner_differences(b, alive, &u);
            assert_eq!(bits(&fast), bits(&portable), "block {k}");
            compared += 1;
        }
    }
    assert!(compared > 4);
    // The sweep: the pass in tasks (the AVX2 sweep of the slots) and in one
    // task (each block added as it comes) against the portable sum of the
    // same lanes' forces, NaN included.
    let mut one_task = vec![[0.0; 3]; u.len()];
    large.clone().pass(&u, &mut one_task, 1);
    let mut fast = vec![[0.0; 3]; u.len()];
    large.pass_keeping_element_forces(&u, &mut fast);
    let mut portable = vec![[0.0; 3]; u.len()];
    let Lanes::F32(set) = &large.lanes else {
        panic!("f32 lanes")
    };
    set.add_to_vertices_portable(&large.elements, &large.vertices, &mut portable);
    let bits = |f: &[V3]| {
        f.iter()
            .map(|v| v.map(|x| if x.is_nan() { u64::MAX } else { x.to_bits() }))
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&fast), bits(&portable));
    assert_eq!(bits(&one_task), bits(&portable));
    assert!(fast.iter().flatten().any(|x| x.is_nan()));
    assert!(
        fast.iter()
            .flatten()
            .filter(|x| x.is_finite() && **x != 0.0)
            .count()
            > 20
    );
}
