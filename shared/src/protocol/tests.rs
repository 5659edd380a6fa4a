//! The wire protocol's unit tests.

use super::*;

/// The layouts documented in docs/protocol.md: sizes a reader in another
/// language relies on. A change here is a protocol change.
#[test]
fn payload_sizes_are_the_documented_ones() {
    assert_eq!(std::mem::size_of::<ToolPose>(), 64);
    assert_eq!(std::mem::size_of::<PoseMsg>(), 24 + 64 * MAX_TOOLS);
    assert_eq!(std::mem::size_of::<ToolForce>(), 136);
    assert_eq!(std::mem::size_of::<ForceMsg>(), 40 + 136 * MAX_TOOLS);
    assert_eq!(std::mem::size_of::<MeshHeader>(), 32);
    assert_eq!(std::mem::size_of::<TopologyHeader>(), 16);
    assert_eq!(std::mem::size_of::<ToolInfo>(), 88);
    assert_eq!(std::mem::size_of::<SceneInfo>(), 64 + 88 * MAX_TOOLS);
    assert_eq!(std::mem::size_of::<RestHeader>(), 80);
    let mut r = RestHeader::default();
    r.set_name("liver.toml");
    assert_eq!(r.name(), "liver.toml");
    r.set_name(&"x".repeat(100));
    assert_eq!(r.name().len(), 64);
    r.vertex_count = 10;
    r.fibre_count = 3;
    assert_eq!(r.slice_len(), Some(16));
    let mut t = ToolInfo::default();
    t.set_name("grasper");
    assert_eq!(t.name(), "grasper");
    // Cut at a character boundary, never inside one.
    t.set_name(&"é".repeat(20));
    assert_eq!(t.name(), "é".repeat(16));
    assert_eq!(std::mem::size_of::<TelemetryTick>(), 88);
    assert_eq!(std::mem::size_of::<LocalPart>(), 64);
    assert_eq!(std::mem::size_of::<LocalPoint>(), 40);
    // docs/protocol.md gives this size and the offsets.
    assert_eq!(std::mem::size_of::<LocalContactMsg>(), 125_256);
    assert_eq!(std::mem::offset_of!(LocalContactMsg, parts), 64);
    assert_eq!(std::mem::offset_of!(LocalContactMsg, points), 768);
    assert_eq!(
        std::mem::offset_of!(LocalContactMsg, compliance_m_per_n),
        41_728
    );
    assert_eq!(std::mem::offset_of!(LocalContactMsg, column_mass), 83_200);
    assert_eq!(
        std::mem::offset_of!(LocalContactMsg, velocities_m_per_s),
        124_672
    );
    assert_eq!(
        std::mem::offset_of!(LocalContactMsg, damping_per_s),
        125_248
    );
    assert_eq!(
        std::mem::size_of::<LocalContactMsg>(),
        64 + 64 * LOCAL_MAX_PARTS
            + 24 * LOCAL_MAX_VERTICES
            + 40 * LOCAL_MAX_POINTS
            + 2 * 8 * LOCAL_COMPLIANCE_LEN
            + 24 * LOCAL_MAX_VERTICES
            + 8
    );
    assert_eq!(
        std::mem::size_of::<TelemetryBatch>(),
        16 + 88 * TELEMETRY_BATCH
    );
    for align in [
        std::mem::align_of::<PoseMsg>(),
        std::mem::align_of::<ForceMsg>(),
        std::mem::align_of::<TelemetryBatch>(),
    ] {
        assert_eq!(align, 8);
    }
}

#[test]
fn version_mismatch_is_refused_clearly() {
    assert!(check_version("force", PROTOCOL_VERSION).is_ok());
    let e = check_version("force", PROTOCOL_VERSION + 1).unwrap_err();
    assert!(e.to_string().contains("version mismatch on force"), "{e}");
}
