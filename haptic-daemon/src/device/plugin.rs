//! A device in a C shared library (`include/hapsim_device.h`), so a lab can
//! wrap the OpenHaptics or Force Dimension SDK in a few lines of C.

use super::{Device, DeviceError, DeviceSpecs, DeviceState};
use crate::math::V3;
use std::ffi::{CString, c_char, c_int, c_void};
use std::path::Path;
use thiserror::Error;

/// The ABI version this daemon speaks.
pub const ABI_VERSION: u32 = 1;

#[repr(C)]
#[derive(Default)]
struct CSpecs {
    max_force_n: f64,
    max_stiffness_n_per_m: f64,
    workspace_min_m: [f64; 3],
    workspace_max_m: [f64; 3],
}

#[repr(C)]
#[derive(Default)]
struct CState {
    position_m: [f64; 3],
    velocity_m_s: [f64; 3],
    gripper: f64,
    buttons: u32,
}

type OpenFn = unsafe extern "C" fn(*mut *mut c_void, *const c_char) -> c_int;
type SpecsFn = unsafe extern "C" fn(*mut c_void, *mut CSpecs) -> c_int;
type HandleFn = unsafe extern "C" fn(*mut c_void) -> c_int;
type ReadFn = unsafe extern "C" fn(*mut c_void, *mut CState) -> c_int;
type WriteFn = unsafe extern "C" fn(*mut c_void, *const f64) -> c_int;
type VoidFn = unsafe extern "C" fn(*mut c_void);
type VersionFn = unsafe extern "C" fn() -> u32;

/// Why a plugin could not be loaded.
#[derive(Debug, Error)]
pub enum PluginError {
    /// dlopen or dlsym failed.
    #[error("{file}: {reason}")]
    Load {
        /// The library.
        file: String,
        /// The loader's message.
        reason: String,
    },
    /// Another ABI version.
    #[error(
        "{file}: plugin ABI version {found}, this daemon speaks {ABI_VERSION} (include/hapsim_device.h)"
    )]
    Version {
        /// The library.
        file: String,
        /// Its version.
        found: u32,
    },
    /// The plugin's open or specs call failed, or its specs are impossible.
    #[error("{file}: {call} failed: {reason}")]
    Call {
        /// The library.
        file: String,
        /// Which function.
        call: &'static str,
        /// What went wrong.
        reason: String,
    },
}

/// A loader error with its causes: libloading's own message is only
/// "dlopen failed" or "dlsym failed", the system's reason (`dlerror`: file
/// not found, wrong architecture, undefined symbol) is its source.
fn describe(e: &libloading::Error) -> String {
    let mut text = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}

/// A loaded plugin device.
pub struct Plugin {
    // Field order matters: the function pointers point into `_lib`, which
    // must outlive every call (it is dropped last).
    handle: *mut c_void,
    enable: HandleFn,
    read: ReadFn,
    write: WriteFn,
    disable: VoidFn,
    close: VoidFn,
    specs: DeviceSpecs,
    _lib: libloading::Library,
}

// SAFETY: the ABI (include/hapsim_device.h) requires the handle to be usable
// from a thread other than the one that opened it (the RT thread), one thread
// at a time; the daemon moves the device to the RT thread once and never
// shares it.
unsafe impl Send for Plugin {}

impl Plugin {
    /// Loads `path` and opens the device with `args`.
    pub fn load(path: &Path, args: &str) -> Result<Self, PluginError> {
        let file = path.display().to_string();
        let load_err = |reason: String| PluginError::Load {
            file: file.clone(),
            reason,
        };
        // SAFETY: loading a library runs its initialisers; the user named
        // this plugin on the command line to be loaded.
        let lib = unsafe { libloading::Library::new(path) }.map_err(|e| load_err(describe(&e)))?;
        macro_rules! sym {
            ($name:literal, $ty:ty) => {{
                // SAFETY: the symbol's type is fixed by the ABI header.
                let s: libloading::Symbol<$ty> = unsafe { lib.get($name) }.map_err(|e| {
                    load_err(format!(
                        "symbol {}: {} (include/hapsim_device.h lists what a plugin exports)",
                        String::from_utf8_lossy($name),
                        describe(&e)
                    ))
                })?;
                *s
            }};
        }
        let version = sym!(b"hapsim_device_abi_version", VersionFn);
        // SAFETY: ABI function without arguments.
        let found = unsafe { version() };
        if found != ABI_VERSION {
            return Err(PluginError::Version { file, found });
        }
        let open = sym!(b"hapsim_device_open", OpenFn);
        let specs_fn = sym!(b"hapsim_device_specs", SpecsFn);
        let mut plugin_handle: *mut c_void = std::ptr::null_mut();
        let c_args = CString::new(args).map_err(|_| PluginError::Call {
            file: file.clone(),
            call: "hapsim_device_open",
            reason: "arguments contain a NUL byte".into(),
        })?;
        // SAFETY: valid out-pointer and NUL-terminated string, per the ABI.
        let rc = unsafe { open(&mut plugin_handle, c_args.as_ptr()) };
        if rc != 0 {
            return Err(PluginError::Call {
                file,
                call: "hapsim_device_open",
                reason: format!("returned {rc}"),
            });
        }
        let close = sym!(b"hapsim_device_close", VoidFn);
        let mut s = CSpecs::default();
        // SAFETY: handle from open, valid out-pointer.
        let rc = unsafe { specs_fn(plugin_handle, &mut s) };
        let finite = [s.max_force_n, s.max_stiffness_n_per_m]
            .iter()
            .all(|x| x.is_finite() && *x > 0.0);
        if rc != 0 || !finite {
            // SAFETY: the handle came from open and is closed once.
            unsafe { close(plugin_handle) };
            return Err(PluginError::Call {
                file,
                call: "hapsim_device_specs",
                reason: if rc != 0 {
                    format!("returned {rc}")
                } else {
                    format!(
                        "max_force_n {} and max_stiffness_n_per_m {} must be positive",
                        s.max_force_n, s.max_stiffness_n_per_m
                    )
                },
            });
        }
        Ok(Self {
            handle: plugin_handle,
            enable: sym!(b"hapsim_device_enable", HandleFn),
            read: sym!(b"hapsim_device_read", ReadFn),
            write: sym!(b"hapsim_device_write_force", WriteFn),
            disable: sym!(b"hapsim_device_disable", VoidFn),
            close,
            specs: DeviceSpecs {
                name: "plugin",
                max_force_n: s.max_force_n,
                max_stiffness_n_per_m: s.max_stiffness_n_per_m,
                workspace_min_m: s.workspace_min_m,
                workspace_max_m: s.workspace_max_m,
            },
            _lib: lib,
        })
    }
}

impl Device for Plugin {
    fn specs(&self) -> DeviceSpecs {
        self.specs
    }

    fn enable(&mut self, _now_ns: u64) -> Result<(), DeviceError> {
        // SAFETY: handle from open, used from one thread.
        match unsafe { (self.enable)(self.handle) } {
            0 => Ok(()),
            rc => Err(DeviceError::Disconnected(format!(
                "hapsim_device_enable returned {rc}"
            ))),
        }
    }

    fn disable(&mut self) {
        // SAFETY: handle from open.
        unsafe { (self.disable)(self.handle) }
    }

    fn read(&mut self, _now_ns: u64) -> Result<DeviceState, DeviceError> {
        let mut s = CState::default();
        // SAFETY: handle from open, valid out-pointer.
        let rc = unsafe { (self.read)(self.handle, &mut s) };
        if rc != 0 {
            return Err(DeviceError::Disconnected(format!(
                "hapsim_device_read returned {rc}"
            )));
        }
        let finite = s
            .position_m
            .iter()
            .chain(&s.velocity_m_s)
            .all(|x| x.is_finite())
            && s.gripper.is_finite();
        if !finite {
            return Err(DeviceError::NonFinite("position, velocity or gripper"));
        }
        Ok(DeviceState {
            position_m: s.position_m,
            velocity_m_s: s.velocity_m_s,
            gripper: s.gripper.clamp(0.0, 1.0),
            buttons: s.buttons,
        })
    }

    fn write_force(&mut self, force_n: V3, _now_ns: u64) -> Result<(), DeviceError> {
        // SAFETY: handle from open; the array outlives the call.
        match unsafe { (self.write)(self.handle, force_n.as_ptr()) } {
            0 => Ok(()),
            rc => Err(DeviceError::Disconnected(format!(
                "hapsim_device_write_force returned {rc}"
            ))),
        }
    }
}

impl Drop for Plugin {
    fn drop(&mut self) {
        // SAFETY: the handle came from open; close is called exactly once,
        // before the library is unloaded (field order).
        unsafe { (self.close)(self.handle) }
    }
}
