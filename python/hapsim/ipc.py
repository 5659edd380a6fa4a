"""Where a user's sessions live: the iceoryx2 root and shared-memory prefix
private to the user who runs them, the same rules as the Rust side
(shared/src/ipc_root.rs): root HAPSIM_IPC_DIR or /tmp/hapsim-<uid>/, created
0700 and refused unless it is a directory of this user that no one else may
enter; prefix hapsim_<uid>_; a /dev/shm object of that prefix made by
another user refused; this user's objects made 0600 once a node exists."""

import os
import stat

import iceoryx2 as iox2

ROOT_ENV = "HAPSIM_IPC_DIR"
SHM_DIR = "/dev/shm"
MAX_ROOT_BYTES = 50


class IpcRootError(RuntimeError):
    """The directory of this user's sessions, or an object in /dev/shm,
    cannot be trusted; the message names it and says what to do."""


def ipc_root():
    """(directory ending with '/', prefix, uid) of this user, checked."""
    uid = os.geteuid()
    d = os.environ.get(ROOT_ENV) or f"/tmp/hapsim-{uid}"
    text = d if d.endswith("/") else d + "/"
    if len(text.encode()) > MAX_ROOT_BYTES:
        raise IpcRootError(f"{d} is {len(text.encode())} bytes long; at most {MAX_ROOT_BYTES}: set {ROOT_ENV} to a shorter path")
    try:
        os.mkdir(d, 0o700)
    except FileExistsError:
        pass
    st = os.lstat(d)
    if not stat.S_ISDIR(st.st_mode):
        kind = "symbolic link" if stat.S_ISLNK(st.st_mode) else "file"
        raise IpcRootError(f"{d} is not a directory but a {kind}: remove it, or set {ROOT_ENV} to another directory")
    if st.st_uid != uid:
        raise IpcRootError(
            f"{d} belongs to uid {st.st_uid}, not to this user (uid {uid}): another user may have made it; remove it as root, or set {ROOT_ENV} to a directory of your own"
        )
    mode = stat.S_IMODE(st.st_mode)
    if mode & 0o077:
        raise IpcRootError(f"{d} has mode {mode:o}: other users may enter or change it; run chmod 700 {d}")
    prefix = f"hapsim_{uid}_"
    for name, path, owner, _ in _objects(prefix):
        if owner != uid:
            raise IpcRootError(
                f"{path} belongs to uid {owner}, not to this user (uid {uid}), yet has this user's prefix: remove it as root"
            )
    return text, prefix, uid


def _objects(prefix):
    try:
        names = os.listdir(SHM_DIR)
    except OSError:
        return
    for name in names:
        if not name.startswith(prefix):
            continue
        path = os.path.join(SHM_DIR, name)
        try:
            st = os.lstat(path)
        except OSError:
            continue
        yield name, path, st.st_uid, st.st_mode


def node(name):
    """An iceoryx2 node named `name` in this user's private root."""
    root, prefix, uid = ipc_root()
    config = iox2.config.default()
    config.global_cfg.root_path = iox2.Path.new(root)
    config.global_cfg.prefix = iox2.FileName.new(prefix)
    n = (
        iox2.NodeBuilder.new()
        .name(iox2.NodeName.new(name))
        .config(config)
        .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
        .create(iox2.ServiceType.Ipc)
    )
    # iceoryx2 leaves its global management segment 0666.
    for _, path, owner, mode in _objects(prefix):
        if owner == uid and stat.S_ISREG(mode) and stat.S_IMODE(mode) & 0o077:
            try:
                os.chmod(path, stat.S_IMODE(mode) & 0o700)
            except OSError:
                pass
    return n
