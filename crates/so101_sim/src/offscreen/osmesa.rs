//! OSMesa: Mesa's off-screen GL into client memory, the fallback where EGL is missing.

use std::ffi::{c_void, CStr};

use libloading::os::unix::{Library, Symbol, RTLD_GLOBAL, RTLD_NOW};

use super::GlError;

const LIBRARY: &str = "libOSMesa.so.8";
const OSMESA_RGBA: u32 = 0x1908;
const GL_UNSIGNED_BYTE: u32 = 0x1401;

type CreateContextExt = unsafe extern "C" fn(u32, i32, i32, i32, *mut c_void) -> *mut c_void;
type MakeCurrent = unsafe extern "C" fn(*mut c_void, *mut c_void, u32, i32, i32) -> u8;
type DestroyContext = unsafe extern "C" fn(*mut c_void);
type GetProcAddress = unsafe extern "C" fn(*const std::ffi::c_char) -> *const c_void;

pub struct OsmesaContext {
    context: *mut c_void,
    /// The default framebuffer OSMesa draws into (MuJoCo itself renders into its own FBO).
    _buffer: Vec<u8>,
    destroy: Symbol<DestroyContext>,
    get_proc_address: Symbol<GetProcAddress>,
    _library: Library,
}

impl OsmesaContext {
    pub fn create(width: u32, height: u32) -> Result<Self, GlError> {
        let error = |what: &str, detail: &dyn std::fmt::Display| {
            GlError::Osmesa(format!("{what}: {detail}"))
        };
        // Global, so that MuJoCo's loader finds OSMesaGetProcAddress (module documentation).
        // SAFETY: loading libOSMesa runs only its initialisers; the functions are looked up by name.
        let library = unsafe { Library::open(Some(LIBRARY), RTLD_NOW | RTLD_GLOBAL) }
            .map_err(|e| error(&format!("cannot load {LIBRARY} (install libosmesa6)"), &e))?;
        let symbol = |name: &[u8]| {
            GlError::Osmesa(format!(
                "{} missing from {LIBRARY}",
                String::from_utf8_lossy(name)
            ))
        };
        // SAFETY: the symbols have the signatures OSMesa's header declares; the buffer handed to OSMesaMakeCurrent is owned by the returned value, as is the context.
        unsafe {
            let create: Symbol<CreateContextExt> = library
                .get(b"OSMesaCreateContextExt")
                .map_err(|_| symbol(b"OSMesaCreateContextExt"))?;
            let make_current: Symbol<MakeCurrent> = library
                .get(b"OSMesaMakeCurrent")
                .map_err(|_| symbol(b"OSMesaMakeCurrent"))?;
            let destroy: Symbol<DestroyContext> = library
                .get(b"OSMesaDestroyContext")
                .map_err(|_| symbol(b"OSMesaDestroyContext"))?;
            let get_proc_address: Symbol<GetProcAddress> = library
                .get(b"OSMesaGetProcAddress")
                .map_err(|_| symbol(b"OSMesaGetProcAddress"))?;
            let context = create(OSMESA_RGBA, 24, 8, 0, std::ptr::null_mut());
            if context.is_null() {
                return Err(GlError::Osmesa("OSMesaCreateContextExt failed".into()));
            }
            let mut buffer = vec![0u8; 4 * width.max(1) as usize * height.max(1) as usize];
            let current = make_current(
                context,
                buffer.as_mut_ptr().cast(),
                GL_UNSIGNED_BYTE,
                width.max(1) as i32,
                height.max(1) as i32,
            );
            if current == 0 {
                destroy(context);
                return Err(GlError::Osmesa("OSMesaMakeCurrent failed".into()));
            }
            Ok(Self {
                context,
                _buffer: buffer,
                destroy,
                get_proc_address,
                _library: library,
            })
        }
    }

    pub fn proc_address(&self, name: &CStr) -> Option<*const c_void> {
        // SAFETY: `name` is NUL-terminated.
        let address = unsafe { (self.get_proc_address)(name.as_ptr()) };
        (!address.is_null()).then_some(address)
    }
}

impl Drop for OsmesaContext {
    fn drop(&mut self) {
        // SAFETY: made by OSMesaCreateContextExt, destroyed once.
        unsafe { (self.destroy)(self.context) };
    }
}
