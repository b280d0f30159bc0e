//! EGL without a window system: a GPU device where the driver offers one (EGL_EXT_platform_device),
//! else Mesa's surfaceless platform (software rendering, no display needed).

use std::ffi::{c_void, CStr};

use khronos_egl as egl;

use super::GlError;

type Egl = egl::DynamicInstance<egl::EGL1_5>;

const PLATFORM_DEVICE_EXT: egl::Enum = 0x313F;
const PLATFORM_SURFACELESS_MESA: egl::Enum = 0x31DD;
const EXTENSIONS: egl::Int = 0x3055;
/// The device extension Mesa marks its software (llvmpipe) device with.
const SOFTWARE_DEVICE: &str = "EGL_MESA_device_software";

type QueryDevices =
    unsafe extern "system" fn(egl::Int, *mut *mut c_void, *mut egl::Int) -> egl::Boolean;
type QueryDeviceString =
    unsafe extern "system" fn(*mut c_void, egl::Int) -> *const std::ffi::c_char;

pub struct EglContext {
    egl: Egl,
    display: egl::Display,
    context: egl::Context,
}

impl EglContext {
    pub fn create() -> Result<Self, GlError> {
        // Opened with RTLD_LOCAL (libloading's default), see the module documentation.
        // SAFETY: loading libEGL runs only its initialisers; the functions are looked up by name.
        let egl = unsafe { Egl::load_required() }.map_err(|error| {
            GlError::Egl(format!(
                "cannot load libEGL.so.1 ({error}): install libegl1 and libegl-mesa0"
            ))
        })?;
        let mut tried = Vec::new();
        for (what, display) in candidate_displays(&egl) {
            match make_context(&egl, display) {
                Ok(context) => {
                    tracing::debug!(display = what, "EGL context made");
                    return Ok(Self {
                        egl,
                        display,
                        context,
                    });
                }
                Err(error) => {
                    let _ = egl.terminate(display);
                    tried.push(format!("{what}: {error}"));
                }
            }
        }
        Err(GlError::Egl(if tried.is_empty() {
            "no EGL display (neither a device nor Mesa's surfaceless platform)".into()
        } else {
            tried.join("; ")
        }))
    }

    pub fn proc_address(&self, name: &CStr) -> Option<*const c_void> {
        self.egl
            .get_proc_address(&name.to_string_lossy())
            .map(|function| function as *const c_void)
    }
}

impl Drop for EglContext {
    fn drop(&mut self) {
        let _ = self.egl.make_current(self.display, None, None, None);
        let _ = self.egl.destroy_context(self.display, self.context);
        let _ = self.egl.terminate(self.display);
    }
}

/// Displays to try in order: hardware devices, Mesa's surfaceless platform, software devices.
fn candidate_displays(egl: &Egl) -> Vec<(String, egl::Display)> {
    let mut hardware = Vec::new();
    let mut software = Vec::new();
    for (index, device, is_software) in devices(egl) {
        let display =
            // SAFETY: `device` came from eglQueryDevicesEXT of this EGL instance.
            unsafe { egl.get_platform_display(PLATFORM_DEVICE_EXT, device, &[egl::ATTRIB_NONE]) };
        if let Ok(display) = display {
            let entry = (format!("EGL device {index}"), display);
            if is_software {
                software.push(entry);
            } else {
                hardware.push(entry);
            }
        }
    }
    // SAFETY: the surfaceless platform takes no native display (NULL) and an empty attribute list.
    let surfaceless = unsafe {
        egl.get_platform_display(
            PLATFORM_SURFACELESS_MESA,
            egl::DEFAULT_DISPLAY,
            &[egl::ATTRIB_NONE],
        )
    };
    hardware.extend(
        surfaceless
            .ok()
            .map(|display| ("Mesa surfaceless platform".to_owned(), display)),
    );
    hardware.extend(software);
    hardware
}

/// The EGL devices (EGL_EXT_device_enumeration) with whether each is a software rasteriser.
fn devices(egl: &Egl) -> Vec<(usize, *mut c_void, bool)> {
    let (Some(query_devices), Some(query_string)) = (
        egl.get_proc_address("eglQueryDevicesEXT"),
        egl.get_proc_address("eglQueryDeviceStringEXT"),
    ) else {
        return Vec::new();
    };
    // SAFETY: looked up by this name, whose signature EGL_EXT_device_enumeration defines.
    let query_devices: QueryDevices = unsafe { std::mem::transmute(query_devices) };
    // SAFETY: looked up by this name, whose signature EGL_EXT_device_query defines.
    let query_string: QueryDeviceString = unsafe { std::mem::transmute(query_string) };
    let mut devices = [std::ptr::null_mut(); 16];
    let mut count: egl::Int = 0;
    // SAFETY: `devices` has room for `devices.len()` entries.
    let ok = unsafe { query_devices(devices.len() as egl::Int, devices.as_mut_ptr(), &mut count) };
    if ok != egl::TRUE {
        return Vec::new();
    }
    devices
        .into_iter()
        .take(count.max(0) as usize)
        .enumerate()
        .map(|(index, device)| {
            // SAFETY: `device` was returned by eglQueryDevicesEXT.
            let extensions = unsafe { query_string(device, EXTENSIONS) };
            let is_software = !extensions.is_null()
                // SAFETY: EGL returns a NUL-terminated string it owns (NULL was checked before).
                && unsafe { CStr::from_ptr(extensions) }
                    .to_string_lossy()
                    .split_whitespace()
                    .any(|extension| extension == SOFTWARE_DEVICE);
            (index, device, is_software)
        })
        .collect()
}

/// An OpenGL context on `display`, current on this thread without any surface
/// (EGL_KHR_surfaceless_context; MuJoCo renders into its own framebuffer object).
fn make_context(egl: &Egl, display: egl::Display) -> Result<egl::Context, String> {
    egl.initialize(display)
        .map_err(|error| format!("eglInitialize: {error}"))?;
    let attributes = [
        egl::SURFACE_TYPE,
        egl::PBUFFER_BIT,
        egl::RENDERABLE_TYPE,
        egl::OPENGL_BIT,
        egl::RED_SIZE,
        8,
        egl::GREEN_SIZE,
        8,
        egl::BLUE_SIZE,
        8,
        egl::ALPHA_SIZE,
        8,
        egl::DEPTH_SIZE,
        24,
        egl::STENCIL_SIZE,
        8,
        egl::NONE,
    ];
    let config = egl
        .choose_first_config(display, &attributes)
        .map_err(|error| format!("eglChooseConfig: {error}"))?
        .ok_or("no RGBA8 / depth 24 / stencil 8 OpenGL config")?;
    egl.bind_api(egl::OPENGL_API)
        .map_err(|error| format!("eglBindAPI(OpenGL): {error}"))?;
    let context = egl
        .create_context(display, config, None, &[egl::NONE])
        .map_err(|error| format!("eglCreateContext: {error}"))?;
    if let Err(error) = egl.make_current(display, None, None, Some(context)) {
        let _ = egl.destroy_context(display, context);
        return Err(format!("eglMakeCurrent without a surface: {error}"));
    }
    Ok(context)
}
