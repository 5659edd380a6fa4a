//! The kernel's unit tests: the dispatched and portable passes agree, storage and layout.

use super::*;
use super::{LowerRows, row_product};
use crate::material::Material;
use crate::material_map::TetMaterials;
use crate::math::Vec3;
use crate::mesh::{BoxSpec, CellSize};

/// The dispatched (AVX2 where available) and portable passes agree bit
/// for bit, and both equal the plain product, in both storages; so
/// does each row computed alone.
#[test]
fn dispatched_and_portable_passes_are_identical() {
    check_passes::<f32>();
    check_passes::<f64>();
}

fn check_passes<S: Storage>() {
    let mesh = BoxSpec::new(Vec3::new(0.03, 0.02, 0.02), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let mat = Material::isotropic(4500.0, 0.45, 1060.0, 0.0).unwrap();
    let model =
        ElasticModel::new(mesh.clone(), TetMaterials::uniform(mat, mesh.tet_count())).unwrap();
    let kernel = Kernel::<S>::new(&model);
    let n = kernel.rows();
    let u: Vec<V3> = (0..n)
        .map(|i| [i as f64 * 1e-6, -(i as f64).sin() * 1e-5, 3e-6])
        .collect();
    // coef (1, 0, 0) makes U(t+1) = -K U: the pass then returns the product.
    let coef = vec![[1.0, 0.0, 0.0]; n];
    let kind = vec![kind::FREE; n];
    let inputs = StepInputs {
        u: &u,
        coef: &coef,
        kind: &kind,
        target: &[],
        fext: &[],
        fmem: &[],
        fnl: &[],
    };
    let run = |portable: bool| {
        let mut ring = vec![[0.0; 4]; kernel.ring_len()];
        let mut next = vec![[0.0; 3]; n];
        let part = Part {
            start: 0,
            end: n,
            deferred_end: 0,
            ring: &mut ring,
            deferred: &mut [],
            next: &mut next,
            spill: &mut [],
        };
        if portable {
            kernel.run_part_portable(&inputs, part);
        } else {
            kernel.run_part(&inputs, part);
        }
        assert!(
            ring.iter().all(|r| *r == [0.0; 4]),
            "the ring must be left zeroed"
        );
        next
    };
    let (a, b) = (run(false), run(true));
    assert_eq!(a, b);
    // A row alone (the predicted step's corrector) adds up as the pass
    // does, to the bit: -K U is what the pass wrote.
    let lower = LowerRows::new(&kernel);
    for (i, negated) in a.iter().enumerate() {
        // The dispatched row (AVX2 where the CPU has it) and the portable one.
        let rows = [
            row_product(&kernel, &lower, &u, i),
            super::rows::row_product_portable(&kernel, &lower, &u, i),
        ];
        for row in rows {
            assert_eq!(
                row.map(f64::to_bits),
                negated.map(|x| (-x).to_bits()),
                "row {i} alone against the pass"
            );
        }
    }
    let mut ku = vec![[0.0; 3]; n];
    kernel.apply(&u, &mut ku);
    for (x, y) in a.iter().zip(&ku) {
        for d in 0..3 {
            assert!(
                (x[d] + y[d]).abs()
                    <= 1e-12 * y.iter().map(|v| v.abs()).fold(1e-30, f64::max) + 1e-18
            );
        }
    }
}
