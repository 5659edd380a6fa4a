//! An OpenGL context without any display: EGL on Mesa's surfaceless
//! platform (`EGL_MESA_platform_surfaceless`), rendering into framebuffer
//! objects only. libEGL is loaded at run time, so the viewer builds and
//! starts without it; only `--snapshot` needs it (Debian: libegl1 and
//! libegl-mesa0, with libgl1-mesa-dri for the software rasterizer).

use khronos_egl as egl;
use std::sync::Arc;

/// `EGL_PLATFORM_SURFACELESS_MESA`.
const PLATFORM_SURFACELESS_MESA: egl::Enum = 0x31DD;

/// Why no headless context could be made.
#[derive(Debug, thiserror::Error)]
pub enum HeadlessError {
    /// libEGL.so.1 could not be loaded.
    #[error(
        "cannot load libEGL.so.1 ({0}); install Mesa's EGL (Debian: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri, as scripts/setup.sh does)"
    )]
    Load(String),
    /// An EGL call failed.
    #[error("EGL {call} failed: {reason}")]
    Egl {
        /// The call.
        call: &'static str,
        /// EGL's error.
        reason: String,
    },
    /// three-d refused the context.
    #[error("OpenGL context unusable: {0}")]
    Gl(String),
}

/// A current surfaceless OpenGL 3.3 core context with three-d on top.
pub struct Headless {
    /// The three-d context.
    pub context: three_d::Context,
    // Kept alive as long as the context.
    _egl: Arc<egl::DynamicInstance<egl::EGL1_5>>,
}

fn failed(call: &'static str) -> impl Fn(egl::Error) -> HeadlessError {
    move |e| HeadlessError::Egl {
        call,
        reason: e.to_string(),
    }
}

impl Headless {
    /// Creates the context and makes it current on this thread.
    pub fn new() -> Result<Self, HeadlessError> {
        // SAFETY: loading libEGL runs its initialisers; it is the system's
        // EGL library, loaded once.
        let instance = unsafe { egl::DynamicInstance::<egl::EGL1_5>::load_required() }
            .map_err(|e| HeadlessError::Load(e.to_string()))?;
        let instance = Arc::new(instance);
        // SAFETY: a platform display with no native display and no attributes.
        let display = unsafe {
            instance.get_platform_display(
                PLATFORM_SURFACELESS_MESA,
                egl::DEFAULT_DISPLAY,
                &[egl::ATTRIB_NONE],
            )
        }
        .map_err(failed("eglGetPlatformDisplay(surfaceless)"))?;
        instance
            .initialize(display)
            .map_err(failed("eglInitialize"))?;
        instance
            .bind_api(egl::OPENGL_API)
            .map_err(failed("eglBindAPI(OpenGL)"))?;
        let attrs = [
            egl::SURFACE_TYPE,
            egl::PBUFFER_BIT,
            egl::RENDERABLE_TYPE,
            egl::OPENGL_BIT,
            egl::NONE,
        ];
        let config = instance
            .choose_first_config(display, &attrs)
            .map_err(failed("eglChooseConfig"))?
            .ok_or(HeadlessError::Egl {
                call: "eglChooseConfig",
                reason: "no OpenGL configuration".into(),
            })?;
        let context_attrs = [
            egl::CONTEXT_MAJOR_VERSION,
            3,
            egl::CONTEXT_MINOR_VERSION,
            3,
            egl::CONTEXT_OPENGL_PROFILE_MASK,
            egl::CONTEXT_OPENGL_CORE_PROFILE_BIT,
            egl::NONE,
        ];
        let ctx = instance
            .create_context(display, config, None, &context_attrs)
            .map_err(failed("eglCreateContext(OpenGL 3.3 core)"))?;
        instance
            .make_current(display, None, None, Some(ctx))
            .map_err(failed("eglMakeCurrent(no surface)"))?;
        let loader = instance.clone();
        // SAFETY: the context is current on this thread; the loader returns
        // EGL's entry points for it.
        let gl = unsafe {
            three_d::context::Context::from_loader_function(|name| {
                loader
                    .get_proc_address(name)
                    .map_or(std::ptr::null(), |f| f as *const _)
            })
        };
        let context = three_d::Context::from_gl_context(Arc::new(gl))
            .map_err(|e| HeadlessError::Gl(e.to_string()))?;
        Ok(Self {
            context,
            _egl: instance,
        })
    }
}
