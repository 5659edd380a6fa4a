"""A client's side of a hapsim session: read force samples and mesh frames
as numpy arrays, publish tool poses. Written from docs/protocol.md on
iceoryx2's Python package (the same version as the Rust crate)."""

import ctypes
import dataclasses
import time
from typing import List, Optional, Sequence, Tuple

import iceoryx2 as iox2
import numpy as np

from . import ipc
from .protocol import (
    MAX_TOOLS,
    PROTOCOL_VERSION,
    TOOL_PRESENT,
    ForceMsg,
    MeshHeader,
    TOOL_KINDS,
    PoseMsg,
    Position,
    RestHeader,
    SceneInfo,
    TopologyHeader,
    Triangle,
)

#: A pose older than this (s) drives no tool (the simulation's default
#: timeout is 50 ms): publish at least this often, even when still.
POSE_TIMEOUT_S = 0.05


class ProtocolError(RuntimeError):
    """A peer sent a payload of another protocol version."""


@dataclasses.dataclass
class ForceSample:
    """One simulation step's force sample (`ForceMsg`), per tool as numpy
    arrays over the scene's `tool_count` tools."""

    seq: int
    #: CLOCK_MONOTONIC (ns) when the step finished.
    t_ns: int
    #: Simulated time (ns).
    sim_time_ns: int
    #: (tools, 3): force of the tissue on each tool (N).
    force_n: np.ndarray
    #: (tools, 3): the tool position each step used (m; zeros: no pose).
    position_m: np.ndarray
    #: (tools, 3, 3): contact stiffness, dF = -K dP (N/m).
    stiffness_n_per_m: np.ndarray
    #: (tools,): seq of the pose the step used (0: none).
    pose_seq: np.ndarray
    #: (tools,): CONTACT | GRIPPING | CUTTING | CATCHING_UP bits.
    flags: np.ndarray

    @staticmethod
    def from_msg(m: ForceMsg) -> "ForceSample":
        n = min(int(m.tool_count), MAX_TOOLS)
        tools = m.tools[:n]
        return ForceSample(
            seq=int(m.seq),
            t_ns=int(m.t_ns),
            sim_time_ns=int(m.sim_time_ns),
            force_n=np.array([list(t.force_n) for t in tools], dtype=float).reshape(n, 3),
            position_m=np.array([list(t.position_m) for t in tools], dtype=float).reshape(n, 3),
            stiffness_n_per_m=np.array(
                [[list(r) for r in t.stiffness_n_per_m] for t in tools], dtype=float
            ).reshape(n, 3, 3),
            pose_seq=np.array([t.pose_seq for t in tools], dtype=np.uint64),
            flags=np.array([t.flags for t in tools], dtype=np.uint32),
        )


@dataclasses.dataclass
class Tool:
    """A tool the scene declares (`[[tool]]`), index = its place in poses
    and force samples."""

    name: str
    kind: str
    fulcrum_m: np.ndarray
    length_m: float
    radius_m: float
    tip_length_m: float


@dataclasses.dataclass
class Scene:
    """What the simulation says about its scene (the `scene` stream)."""

    tools: List[Tool]
    #: The organ's rest bounding box (min, max), m.
    bounds_m: Tuple[np.ndarray, np.ndarray]
    vertex_count: int
    tet_count: int

    @staticmethod
    def from_msg(m: SceneInfo) -> "Scene":
        tools = []
        for t in m.tools[: min(int(m.tool_count), MAX_TOOLS)]:
            name = bytes(t.name).split(b"\0", 1)[0].decode("utf-8", "replace")
            tools.append(
                Tool(
                    name=name,
                    kind=TOOL_KINDS.get(int(t.kind), f"kind {t.kind}"),
                    fulcrum_m=np.array(list(t.fulcrum_m)),
                    length_m=float(t.length_m),
                    radius_m=float(t.radius_m),
                    tip_length_m=float(t.tip_length_m),
                )
            )
        bounds = (np.array(list(m.bounds_min_m)), np.array(list(m.bounds_max_m)))
        return Scene(tools, bounds, int(m.vertex_count), int(m.tet_count))


@dataclasses.dataclass
class Rest:
    """The scene at rest (the `rest` and `surface0` streams): what a client
    needs instead of the scene file."""

    #: The scene's name (its file, or the embedded liver's).
    name: str
    #: (vertices, 3) float64, metres: rest positions, in mesh-frame order.
    positions_m: np.ndarray
    #: (fibres, 2, 3) float64: per anisotropic tetrahedron its centroid and
    #: its fibre direction times its first edge length (m).
    fibres: np.ndarray
    #: (triangles, 3) uint32: the surface as built, before any cut (None
    #: until `surface0` has arrived); a later surface's other faces are cuts.
    original_triangles: Optional[np.ndarray]


@dataclasses.dataclass
class MeshFrame:
    """The organ's state: positions of every vertex (m) and the current
    outward surface triangles (vertex indices)."""

    frame_seq: int
    t_ns: int
    topology_version: int
    #: (vertices, 3) float64, metres, scene frame.
    positions_m: np.ndarray
    #: (triangles, 3) uint32, or None until the topology has arrived.
    triangles: Optional[np.ndarray]

    def bounds_m(self) -> Tuple[np.ndarray, np.ndarray]:
        """Bounding box (min, max) of the surface vertices (all vertices
        before the topology arrived), m."""
        if self.triangles is not None and len(self.triangles):
            p = self.positions_m[np.unique(self.triangles)]
        else:
            p = self.positions_m
        return p.min(axis=0), p.max(axis=0)


def _verifier() -> "iox2.AttributeVerifier":
    return iox2.AttributeVerifier.new().require(
        iox2.AttributeKey.new("hapsim.protocol"),
        iox2.AttributeValue.new(str(PROTOCOL_VERSION)),
    )


def open_stream(node, session: str, stream: str, payload, buffer: int):
    """Opens (or creates) publish-subscribe stream `stream` of `session`
    with the protocol's settings (docs/protocol.md): the port factory."""
    return (
        node.service_builder(iox2.ServiceName.new(f"hapsim/{session}/{stream}"))
        .publish_subscribe(payload)
        .max_publishers(2)
        .max_subscribers(8)
        .history_size(1)
        .subscriber_max_buffer_size(buffer)
        .enable_safe_overflow(True)
        .open_or_create_with_attributes(_verifier())
    )


def _drain(subscriber, what: str, header: bool = False):
    """Yields every sample waiting on `subscriber` with its payload (or, for a
    slice stream, its user header) checked for the protocol version."""
    while True:
        sample = subscriber.receive()
        if sample is None:
            return
        m = (sample.user_header() if header else sample.payload()).contents
        if m.version != PROTOCOL_VERSION:
            raise ProtocolError(f"{what} of protocol version {m.version}")
        yield sample, m


def _wait(fetch, ready, what: str, session: str, timeout_s: float):
    """Polls `fetch()` until `ready(value)`, at most `timeout_s`."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        value = fetch()
        if ready(value):
            return value
        time.sleep(0.005)
    raise TimeoutError(f"no {what} on session {session!r} within {timeout_s} s: is sim-server running?")


class Session:
    """Attach to session `name` (sim-server's `--session`, default
    "default"). Opens the streams a client uses with the protocol's
    settings (any start order: until the simulation runs, nothing arrives).

    >>> with Session("default") as s:          # doctest: +SKIP
    ...     frame = s.wait_mesh()
    ...     s.publish_pose(frame.bounds_m()[1])
    ...     print(s.latest_force())
    """

    def __init__(self, name: str = "default", node_name: str = "hapsim-python") -> None:
        iox2.set_log_level(iox2.LogLevel.Error)
        self.name = name
        self._node = ipc.node(node_name)
        self._forces = (
            self._service("force", ForceMsg, 1024).subscriber_builder().buffer_size(1024).create()
        )
        self._pose_service = self._service("pose", PoseMsg, 1)
        self._pose_pub = None
        self._mesh = self._slice_service("mesh", Position, MeshHeader).subscriber_builder().create()
        self._topology = (
            self._slice_service("topology", Triangle, TopologyHeader).subscriber_builder().create()
        )
        self._scene_sub = self._service("scene", SceneInfo, 1).subscriber_builder().create()
        self._scene: Optional[Scene] = None
        self._rest_sub = self._slice_service("rest", Position, RestHeader).subscriber_builder().create()
        self._surface0 = (
            self._slice_service("surface0", Triangle, TopologyHeader).subscriber_builder().create()
        )
        self._rest: Optional[Rest] = None
        self._original: Optional[np.ndarray] = None
        self._pose_ready = (
            self._node.service_builder(iox2.ServiceName.new(f"hapsim/{name}/pose-ready"))
            .event()
            .max_notifiers(2)
            .max_listeners(8)
            .open_or_create_with_attributes(_verifier())
            .notifier_builder()
            .create()
        )
        self._seq = 0
        self._triangles: Optional[np.ndarray] = None
        self._topology_version = -1
        self._frame: Optional[MeshFrame] = None

    # -- services ---------------------------------------------------------

    def _service(self, stream: str, payload, buffer: int):
        return open_stream(self._node, self.name, stream, payload, buffer)

    def _slice_service(self, stream: str, element, header):
        return (
            self._node.service_builder(iox2.ServiceName.new(f"hapsim/{self.name}/{stream}"))
            .publish_subscribe(iox2.Slice[element])
            .user_header(header)
            .max_publishers(2)
            .max_subscribers(8)
            .history_size(1)
            .subscriber_max_buffer_size(2)
            .enable_safe_overflow(True)
            .open_or_create_with_attributes(_verifier())
        )

    # -- forces -----------------------------------------------------------

    def forces(self) -> List[ForceSample]:
        """Every force sample received since the last call, oldest first
        (up to 1024 are kept between calls; `seq` gaps show losses)."""
        return [ForceSample.from_msg(m) for _, m in _drain(self._forces, "force sample")]

    def latest_force(self) -> Optional[ForceSample]:
        """The newest force sample (older ones are dropped), or None."""
        got = self.forces()
        return got[-1] if got else None

    # -- mesh -------------------------------------------------------------

    def _receive_topology(self) -> None:
        for sample, h in _drain(self._topology, "topology", header=True):
            n = int(h.triangle_count)
            view = sample.payload().as_memory_view()
            tris = np.frombuffer(view, dtype=np.uint32, count=3 * n).reshape(n, 3).copy()
            self._triangles, self._topology_version = tris, int(h.topology_version)

    def mesh(self) -> Optional[MeshFrame]:
        """The newest mesh frame (None before the first): positions copied
        out of shared memory, with the newest surface triangles."""
        self._receive_topology()
        for sample, h in _drain(self._mesh, "mesh frame", header=True):
            n = int(h.vertex_count)
            view = sample.payload().as_memory_view()
            positions = np.frombuffer(view, dtype=np.float32, count=3 * n).reshape(n, 3)
            self._frame = MeshFrame(
                frame_seq=int(h.frame_seq),
                t_ns=int(h.t_ns),
                topology_version=int(h.topology_version),
                positions_m=positions.astype(np.float64),
                triangles=None,
            )
        if self._frame is not None and self._topology_version == self._frame.topology_version:
            self._frame.triangles = self._triangles
        return self._frame

    def wait_mesh(self, timeout_s: float = 10.0, with_surface: bool = True) -> MeshFrame:
        """Waits for a mesh frame (and, by default, its surface triangles)."""
        return _wait(
            self.mesh,
            lambda f: f is not None and (f.triangles is not None or not with_surface),
            "mesh frame",
            self.name,
            timeout_s,
        )

    def organ_bounds_m(self, timeout_s: float = 10.0) -> Tuple[np.ndarray, np.ndarray]:
        """The organ's bounding box (min, max; m) from its surface now."""
        return self.wait_mesh(timeout_s).bounds_m()

    # -- scene ------------------------------------------------------------

    def scene(self) -> Optional[Scene]:
        """The scene's tools and organ bounds, once the simulation has sent
        them (None before)."""
        for _, m in _drain(self._scene_sub, "scene info"):
            self._scene = Scene.from_msg(m)
        return self._scene

    def wait_scene(self, timeout_s: float = 10.0) -> Scene:
        """Waits for the scene info (the simulation re-sends it to late
        joiners with its next mesh frame)."""
        return _wait(self.scene, lambda s: s is not None, "scene info", self.name, timeout_s)

    def rest(self) -> Optional[Rest]:
        """The scene at rest: name, rest positions, fibres and the uncut
        surface, once the simulation has sent them (None before)."""
        for sample, h in _drain(self._surface0, "surface0", header=True):
            k = int(h.triangle_count)
            view = sample.payload().as_memory_view()
            self._original = np.frombuffer(view, dtype=np.uint32, count=3 * k).reshape(k, 3).copy()
        for sample, h in _drain(self._rest_sub, "rest", header=True):
            n, f = int(h.vertex_count), int(h.fibre_count)
            view = sample.payload().as_memory_view()
            data = np.frombuffer(view, dtype=np.float32, count=3 * (n + 2 * f)).reshape(-1, 3)
            self._rest = Rest(
                name=bytes(h.name).split(b"\0", 1)[0].decode("utf-8", "replace"),
                positions_m=data[:n].astype(np.float64),
                fibres=data[n:].astype(np.float64).reshape(f, 2, 3),
                original_triangles=None,
            )
        if self._rest is not None:
            self._rest.original_triangles = self._original
        return self._rest

    def wait_rest(self, timeout_s: float = 10.0) -> Rest:
        """Waits for the scene at rest with its uncut surface."""
        return _wait(
            self.rest,
            lambda r: r is not None and r.original_triangles is not None,
            "rest shape",
            self.name,
            timeout_s,
        )

    # -- poses ------------------------------------------------------------

    def publish_pose(
        self,
        tip_m: Sequence[float],
        jaw_opening: float = 1.0,
        tool: int = 0,
        tool_count: int = 1,
    ) -> int:
        """Publishes tool `tool`'s tip (m, scene frame) and jaw opening
        (0 closed .. 1 open); tools other than `tool` are withdrawn. Returns
        the pose's seq (counting from 1). Publish again within
        POSE_TIMEOUT_S, or the tool lets go. The session has at most two pose
        publishers (a running haptic-daemon is one)."""
        if not 0 <= tool < tool_count <= MAX_TOOLS:
            raise ValueError(f"tool {tool} of {tool_count}: at most {MAX_TOOLS} tools")
        tip = [float(x) for x in tip_m]
        if len(tip) != 3 or not all(np.isfinite(tip)):
            raise ValueError(f"tip_m must be 3 finite numbers, got {tip_m!r}")
        if not 0.0 <= float(jaw_opening) <= 1.0:  # NaN fails this too
            raise ValueError(
                f"jaw_opening must be between 0 (closed) and 1 (open), got {jaw_opening!r}"
            )
        if self._pose_pub is None:
            self._pose_pub = self._pose_service.publisher_builder().create()
        self._seq += 1
        msg = PoseMsg(version=PROTOCOL_VERSION, tool_count=tool_count, seq=self._seq)
        msg.t_ns = time.monotonic_ns()
        t = msg.tools[tool]
        t.tip_m[:] = tip
        t.jaw_opening = float(jaw_opening)
        t.flags = TOOL_PRESENT
        self._pose_pub.send_copy(msg)
        self._pose_ready.notify()
        return self._seq

    # -- lifetime ---------------------------------------------------------

    def close(self) -> None:
        """Releases the ports (also on garbage collection)."""
        for attr in ("_pose_pub", "_forces", "_mesh", "_topology", "_scene_sub", "_pose_ready"):
            port = getattr(self, attr, None)
            if port is not None and hasattr(port, "delete"):
                port.delete()
            setattr(self, attr, None)

    def __enter__(self) -> "Session":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
