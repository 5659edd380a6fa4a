"""The hapsim shared-memory protocol, version 1 (docs/protocol.md): the
payloads as ctypes structures with the type names iceoryx2 compares, and
the constants. Sizes are checked on import."""

import ctypes

PROTOCOL_VERSION = 1
MAX_TOOLS = 4

#: `ToolPose.flags`: the tool is in use.
TOOL_PRESENT = 1
#: `ToolForce.flags` bits.
CONTACT = 1
GRIPPING = 2
CUTTING = 4
#: The simulated tool is not at the pose asked for (coming back in slowly
#: after a let-go or a jump, or held outside the tissue): render the force
#: as it is, do not extrapolate it by the hand's motion.
CATCHING_UP = 8


class ToolPose(ctypes.Structure):
    """One tool's pose (64 bytes)."""

    _fields_ = [
        ("tip_m", ctypes.c_double * 3),
        ("shaft_dir", ctypes.c_double * 3),  # reserved: zeros
        ("jaw_opening", ctypes.c_double),
        ("buttons", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
    ]


class PoseMsg(ctypes.Structure):
    """Client -> simulation: the latest pose of every tool (280 bytes)."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("tool_count", ctypes.c_uint32),
        ("seq", ctypes.c_uint64),
        ("t_ns", ctypes.c_uint64),
        ("tools", ToolPose * MAX_TOOLS),
    ]

    @staticmethod
    def type_name() -> str:
        return "hapsim.PoseMsg.v1"


class ToolForce(ctypes.Structure):
    """One tool's share of a simulation step (136 bytes)."""

    _fields_ = [
        ("position_m", ctypes.c_double * 3),
        ("force_n", ctypes.c_double * 3),
        ("stiffness_n_per_m", (ctypes.c_double * 3) * 3),
        ("pose_seq", ctypes.c_uint64),
        ("flags", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32),
    ]


class ForceMsg(ctypes.Structure):
    """Simulation -> clients: one sample per step (584 bytes)."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("tool_count", ctypes.c_uint32),
        ("seq", ctypes.c_uint64),
        ("t_ns", ctypes.c_uint64),
        ("sim_time_ns", ctypes.c_uint64),
        ("step_period_ns", ctypes.c_uint64),
        ("tools", ToolForce * MAX_TOOLS),
    ]

    @staticmethod
    def type_name() -> str:
        return "hapsim.ForceMsg.v1"


class MeshHeader(ctypes.Structure):
    """User header of the `mesh` slice stream (32 bytes)."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("vertex_count", ctypes.c_uint32),
        ("frame_seq", ctypes.c_uint64),
        ("topology_version", ctypes.c_uint64),
        ("t_ns", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "hapsim.MeshHeader.v1"


class TopologyHeader(ctypes.Structure):
    """User header of the `topology` slice stream (16 bytes)."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("triangle_count", ctypes.c_uint32),
        ("topology_version", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "hapsim.TopologyHeader.v1"


#: `ToolInfo.kind` values.
TOOL_KINDS = {0: "grasper", 1: "hook", 2: "cavitron"}


class ToolInfo(ctypes.Structure):
    """One declared tool in `SceneInfo` (88 bytes)."""

    _fields_ = [
        ("name", ctypes.c_uint8 * 32),
        ("kind", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32),
        ("fulcrum_m", ctypes.c_double * 3),
        ("length_m", ctypes.c_double),
        ("radius_m", ctypes.c_double),
        ("tip_length_m", ctypes.c_double),
    ]


class SceneInfo(ctypes.Structure):
    """Simulation -> clients, once at start (history 1): the scene's tools and
    the organ's rest bounding box (416 bytes)."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("tool_count", ctypes.c_uint32),
        ("vertex_count", ctypes.c_uint32),
        ("tet_count", ctypes.c_uint32),
        ("bounds_min_m", ctypes.c_double * 3),
        ("bounds_max_m", ctypes.c_double * 3),
        ("tools", ToolInfo * MAX_TOOLS),
    ]

    @staticmethod
    def type_name() -> str:
        return "hapsim.SceneInfo.v1"


class RestHeader(ctypes.Structure):
    """User header of the `rest` slice stream (80 bytes): the slice holds
    `vertex_count` rest positions, then `fibre_count` pairs (centroid of an
    anisotropic tetrahedron, its fibre direction times its first edge)."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("vertex_count", ctypes.c_uint32),
        ("fibre_count", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32),
        ("name", ctypes.c_uint8 * 64),
    ]

    @staticmethod
    def type_name() -> str:
        return "hapsim.RestHeader.v1"


class Position(ctypes.Structure):
    """A `mesh` slice element: a position in metres as Rust's `[f32; 3]`."""

    _fields_ = [("xyz", ctypes.c_float * 3)]

    @staticmethod
    def type_name() -> str:
        return "[f32; 3]"


class Triangle(ctypes.Structure):
    """A `topology` slice element: vertex indices as Rust's `[u32; 3]`."""

    _fields_ = [("v", ctypes.c_uint32 * 3)]

    @staticmethod
    def type_name() -> str:
        return "[u32; 3]"


for _t, _size in [
    (ToolPose, 64),
    (PoseMsg, 280),
    (ToolForce, 136),
    (ForceMsg, 584),
    (MeshHeader, 32),
    (TopologyHeader, 16),
    (ToolInfo, 88),
    (SceneInfo, 64 + 88 * MAX_TOOLS),
    (RestHeader, 80),
    (Position, 12),
    (Triangle, 12),
]:
    assert ctypes.sizeof(_t) == _size, f"{_t.__name__}: {ctypes.sizeof(_t)} bytes, expected {_size}"
