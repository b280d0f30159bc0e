//! A headless OpenGL context for MuJoCo's offscreen renderer: EGL (the GPU driver's where one is
//! installed, else Mesa's software rasteriser without any display), or OSMesa as the fallback.
//!
//! Both libraries are opened at run time rather than linked, so the node starts (and simulates)
//! on machines without them. MuJoCo finds its GL functions through whichever platform library the
//! process has loaded (its glad loader looks for eglGetProcAddress / OSMesaGetProcAddress among the
//! global symbols, then among the loaded libraries by name); libEGL is therefore opened locally and
//! libOSMesa globally, so that an EGL attempt that failed never shadows the OSMesa fallback.
#![allow(unsafe_code)]

mod egl;
mod osmesa;

use std::{
    ffi::{c_char, c_void, CStr},
    marker::PhantomData,
};

/// Which GL platform to use (`--renderer`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RendererChoice {
    /// EGL, then OSMesa if EGL is unavailable.
    Auto,
    Egl,
    Osmesa,
}

#[derive(Debug, thiserror::Error)]
pub enum GlError {
    #[error("EGL: {0}")]
    Egl(String),
    #[error("OSMesa: {0}")]
    Osmesa(String),
    #[error("no headless OpenGL context could be made: {egl}; {osmesa}")]
    Neither {
        egl: Box<GlError>,
        osmesa: Box<GlError>,
    },
}

/// An OpenGL context current on the thread that made it (it must stay on that thread).
pub struct GlContext {
    platform: Platform,
    /// GL_RENDERER and GL_VERSION, for the log.
    pub description: String,
    /// Not Send: the context is current on the thread that made it, and what renders with it
    /// (mujoco::render::RenderContext borrows it) relies on that.
    _current_on_this_thread: PhantomData<*const ()>,
}

enum Platform {
    // Boxed: the EGL instance holds its whole function table.
    Egl(Box<egl::EglContext>),
    Osmesa(osmesa::OsmesaContext),
}

impl GlContext {
    /// Makes a context with a default framebuffer of at least `width` x `height` (OSMesa renders
    /// into client memory of that size; EGL needs none) and makes it current on this thread.
    pub fn create(choice: RendererChoice, width: u32, height: u32) -> Result<Self, GlError> {
        let platform = match choice {
            RendererChoice::Egl => Platform::Egl(Box::new(egl::EglContext::create()?)),
            RendererChoice::Osmesa => {
                Platform::Osmesa(osmesa::OsmesaContext::create(width, height)?)
            }
            RendererChoice::Auto => match egl::EglContext::create() {
                Ok(context) => Platform::Egl(Box::new(context)),
                Err(egl_error) => {
                    tracing::warn!(error = %egl_error, "EGL unavailable, trying OSMesa");
                    match osmesa::OsmesaContext::create(width, height) {
                        Ok(context) => Platform::Osmesa(context),
                        Err(osmesa_error) => {
                            return Err(GlError::Neither {
                                egl: Box::new(egl_error),
                                osmesa: Box::new(osmesa_error),
                            })
                        }
                    }
                }
            },
        };
        let description = match &platform {
            Platform::Egl(context) => describe(|name| context.proc_address(name)),
            Platform::Osmesa(context) => describe(|name| context.proc_address(name)),
        };
        Ok(Self {
            platform,
            description,
            _current_on_this_thread: PhantomData,
        })
    }

    /// "egl" or "osmesa".
    pub fn platform_name(&self) -> &'static str {
        match self.platform {
            Platform::Egl(_) => "egl",
            Platform::Osmesa(_) => "osmesa",
        }
    }
}

const GL_RENDERER: u32 = 0x1F01;
const GL_VERSION: u32 = 0x1F02;

/// "renderer, version" of the current context, read through the platform's glGetString.
fn describe(proc_address: impl Fn(&CStr) -> Option<*const c_void>) -> String {
    let Some(get_string) = proc_address(c"glGetString") else {
        return "unknown renderer".into();
    };
    let get_string: extern "system" fn(u32) -> *const c_char =
        // SAFETY: glGetString has had this signature since OpenGL 1.0.
        unsafe { std::mem::transmute(get_string) };
    let text = |name| {
        let value = get_string(name);
        if value.is_null() {
            "?".to_owned()
        } else {
            // SAFETY: glGetString returns a static NUL-terminated string (NULL was handled above).
            unsafe { CStr::from_ptr(value) }
                .to_string_lossy()
                .into_owned()
        }
    };
    format!("{}, OpenGL {}", text(GL_RENDERER), text(GL_VERSION))
}
