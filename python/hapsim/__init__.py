"""hapsim: attach Python to a running hapsim session (sim-server,
haptic-daemon, viewer) over shared memory.

    from hapsim import Session
    with Session("default") as s:
        lo, hi = s.organ_bounds_m()
        s.publish_pose([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2]])
        print(s.latest_force())

The payloads and rules are those of docs/protocol.md (version 1)."""

from .protocol import (
    CATCHING_UP,
    CONTACT,
    CUTTING,
    GRIPPING,
    MAX_TOOLS,
    PROTOCOL_VERSION,
    TOOL_PRESENT,
    ForceMsg,
    MeshHeader,
    PoseMsg,
    TopologyHeader,
)
from .session import (
    POSE_TIMEOUT_S,
    ForceSample,
    MeshFrame,
    ProtocolError,
    Rest,
    Scene,
    Session,
    Tool,
)

__all__ = [
    "CATCHING_UP",
    "CONTACT",
    "CUTTING",
    "GRIPPING",
    "MAX_TOOLS",
    "POSE_TIMEOUT_S",
    "PROTOCOL_VERSION",
    "TOOL_PRESENT",
    "ForceMsg",
    "ForceSample",
    "MeshFrame",
    "MeshHeader",
    "PoseMsg",
    "ProtocolError",
    "Rest",
    "Scene",
    "Session",
    "Tool",
    "TopologyHeader",
]
__version__ = "0.1.0"
