#!/usr/bin/env bash
# Prepares a fresh Debian machine to build and test the project. Idempotent.
# The build needs a Rust toolchain (>= 1.95) and a C compiler; the viewer's
# snapshots (and the tests that take them) need Mesa's EGL with its software
# rasterizer (loaded at run time, no display needed); the Python backend
# example needs iceoryx2's Python package; the writers' tests need meshio and VTK;
# the remote-session tests need unshare and openssl.
set -euo pipefail
need_apt=()
command -v cc >/dev/null 2>&1 || need_apt+=(gcc)
command -v pkg-config >/dev/null 2>&1 || need_apt+=(pkg-config)
command -v python3 >/dev/null 2>&1 || need_apt+=(python3 python3-pip)
# The remote-session tests: a private mount and time namespace (unshare) and
# a lab CA for TLS (openssl).
command -v unshare >/dev/null 2>&1 || need_apt+=(util-linux)
command -v openssl >/dev/null 2>&1 || need_apt+=(openssl)
if ! { ldconfig -p 2>/dev/null || /sbin/ldconfig -p 2>/dev/null; } | grep 'libEGL_mesa\.so\.0' >/dev/null; then
  need_apt+=(libegl1 libegl-mesa0 libgl1-mesa-dri)
fi
if [ ${#need_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" -eq 0 ]; then apt-get update -qq && apt-get install -y -qq "${need_apt[@]}";
  else sudo apt-get update -qq && sudo apt-get install -y -qq "${need_apt[@]}"; fi
fi
# The out-of-process backend example and its test: iceoryx2's Python package,
# the same version as the Rust crate.
if ! python3 -c 'import iceoryx2' >/dev/null 2>&1; then
  python3 -m pip install --quiet --disable-pip-version-check iceoryx2==0.10.0 2>/dev/null \
    || python3 -m pip install --quiet --disable-pip-version-check --break-system-packages iceoryx2==0.10.0
fi
# The writers' tests read the files back with independent readers: meshio,
# and VTK's own (the library ParaView is built on; a 140 MB wheel).
if ! python3 -c 'import meshio' >/dev/null 2>&1; then
  python3 -m pip install --quiet --disable-pip-version-check meshio==5.3.5 2>/dev/null \
    || python3 -m pip install --quiet --disable-pip-version-check --break-system-packages meshio==5.3.5
fi
if ! python3 -c 'import vtkmodules.vtkIOXML' >/dev/null 2>&1; then
  python3 -m pip install --quiet --disable-pip-version-check vtk==9.7.2 2>/dev/null \
    || python3 -m pip install --quiet --disable-pip-version-check --break-system-packages vtk==9.7.2
fi
# `sim-server mesh`: fTetWild's Python wheel (MPL-2.0, 3 MB). --no-deps: its
# pyvista front end (and matplotlib) is not used; the worker loads the
# compiled wrapper itself and needs only numpy (meshio's).
if ! python3 -c 'import importlib.util as u; assert u.find_spec("pytetwild")' >/dev/null 2>&1; then
  python3 -m pip install --quiet --disable-pip-version-check --no-deps pytetwild==0.4.2 2>/dev/null \
    || python3 -m pip install --quiet --disable-pip-version-check --no-deps --break-system-packages pytetwild==0.4.2
fi
if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: installing the Rust toolchain with rustup" >&2
  curl --proto '=https' --tlsv1.2 -sSf https://sh.rustup.rs | sh -s -- -y --profile minimal
  # shellcheck disable=SC1091
  . "$HOME/.cargo/env"
fi
rustc_minor=$(rustc --version | sed -E 's/^rustc 1\.([0-9]+).*/\1/')
if [ "$rustc_minor" -lt 95 ]; then
  echo "setup: rustc 1.95 or newer is needed (found $(rustc --version)); run: rustup update stable" >&2
  exit 1
fi
