//! A safe wrapper over the few parts of the MuJoCo 2.2.2 C API the simulation uses: loading a
//! model, stepping it, and reading and writing its state. All raw pointers stay inside this module
//! (the generated bindings are private to it).
#![allow(unsafe_code)]

mod edit;
mod ffi;
pub mod render;

use std::{
    ffi::{c_char, CStr, CString},
    path::Path,
    ptr::NonNull,
    sync::Once,
};

#[derive(Debug, thiserror::Error)]
pub enum MujocoError {
    #[error("cannot load MuJoCo model {path}: {message}")]
    Load { path: String, message: String },
    #[error("MuJoCo could not allocate data for the model")]
    MakeData,
    #[error("model path {0:?} contains a NUL byte")]
    BadPath(String),
    #[error("virtual file system: {0}")]
    Vfs(String),
}

/// Kinds of named model elements the node looks up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjectKind {
    Body,
    Joint,
    Geom,
    Site,
    Actuator,
    Camera,
    Material,
    Light,
}

impl ObjectKind {
    fn raw(self) -> i32 {
        (match self {
            Self::Body => ffi::mjOBJ_BODY,
            Self::Joint => ffi::mjOBJ_JOINT,
            Self::Geom => ffi::mjOBJ_GEOM,
            Self::Site => ffi::mjOBJ_SITE,
            Self::Actuator => ffi::mjOBJ_ACTUATOR,
            Self::Camera => ffi::mjOBJ_CAMERA,
            Self::Material => ffi::mjOBJ_MATERIAL,
            Self::Light => ffi::mjOBJ_LIGHT,
        }) as i32
    }
}

/// Routes MuJoCo's errors and warnings into the node's log. MuJoCo's own default handler prints
/// "Press Enter to exit", writes MUJOCO_LOG.TXT into the working directory and calls exit(1).
pub fn install_log_handlers() {
    static INSTALL: Once = Once::new();
    // SAFETY: the handlers are plain function pointers, written once before any model loads.
    INSTALL.call_once(|| unsafe {
        ffi::mju_user_error = Some(on_mujoco_error);
        ffi::mju_user_warning = Some(on_mujoco_warning);
    });
}

unsafe extern "C" fn on_mujoco_error(message: *const c_char) {
    // SAFETY: MuJoCo passes a NUL-terminated message or NULL, which text_from_c handles.
    let text = unsafe { text_from_c(message) };
    tracing::error!(target: "so101_sim::mujoco", "MuJoCo fatal error: {text}");
    // MuJoCo's state is undefined after an error and the handler must not return into it.
    std::process::exit(1);
}

unsafe extern "C" fn on_mujoco_warning(message: *const c_char) {
    // SAFETY: MuJoCo passes a NUL-terminated message or NULL, which text_from_c handles.
    let text = unsafe { text_from_c(message) };
    tracing::warn!(target: "so101_sim::mujoco", "MuJoCo warning: {text}");
}

unsafe fn text_from_c(message: *const c_char) -> String {
    if message.is_null() {
        return String::new();
    }
    // SAFETY: the caller passes a NUL-terminated string that outlives this call (NULL was handled above).
    unsafe { CStr::from_ptr(message) }
        .to_string_lossy()
        .into_owned()
}

/// MuJoCo library version as "2.2.2".
pub fn version() -> String {
    // SAFETY: no arguments and no state.
    let number = unsafe { ffi::mj_version() };
    format!("{}.{}.{}", number / 100, number / 10 % 10, number % 10)
}

/// A compiled model and its simulation state.
pub struct Simulation {
    model: NonNull<ffi::mjModel>,
    data: NonNull<ffi::mjData>,
}

impl std::fmt::Debug for Simulation {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        formatter
            .debug_struct("Simulation")
            .field("time", &self.time())
            .finish_non_exhaustive()
    }
}

// SAFETY: The model and data are owned exclusively; MuJoCo keeps no thread-local state for them.
unsafe impl Send for Simulation {}

impl Simulation {
    /// Loads and compiles an MJCF file.
    pub fn from_xml_file(path: &Path) -> Result<Self, MujocoError> {
        install_log_handlers();
        let display = path.display().to_string();
        let c_path =
            CString::new(display.clone()).map_err(|_| MujocoError::BadPath(display.clone()))?;
        let model = load(&c_path, std::ptr::null(), &display)?;
        Self::with_model(model)
    }

    /// Compiles MJCF text held in memory. `name` is a file path: its directory is where files the
    /// text refers to (includes, textures) are looked up.
    pub fn from_xml_text(xml: &str, name: &str) -> Result<Self, MujocoError> {
        install_log_handlers();
        if xml.is_empty() {
            // mj_makeEmptyFileVFS treats an empty file as a fatal error.
            return Err(MujocoError::Vfs(format!("{name} is empty")));
        }
        let c_name = CString::new(name).map_err(|_| MujocoError::BadPath(name.to_owned()))?;
        let size = i32::try_from(xml.len())
            .map_err(|_| MujocoError::Vfs("model text too large".into()))?;
        // mjVFS holds 2000 file names inline (about 2 MB): keep it off the stack.
        // SAFETY: mjVFS is plain C data (counts, arrays, pointers) for which all zeros is valid.
        let mut vfs: Box<ffi::mjVFS> = unsafe { Box::new_zeroed().assume_init() };
        // SAFETY: `vfs` is an owned, writable mjVFS.
        unsafe { ffi::mj_defaultVFS(vfs.as_mut()) };
        // SAFETY: `vfs` was initialised by mj_defaultVFS and `c_name` is NUL-terminated.
        let status = unsafe { ffi::mj_makeEmptyFileVFS(vfs.as_mut(), c_name.as_ptr(), size) };
        if status != 0 {
            return Err(MujocoError::Vfs(format!(
                "mj_makeEmptyFileVFS returned {status}"
            )));
        }
        // SAFETY: `vfs` was initialised by mj_defaultVFS and `c_name` is NUL-terminated.
        let index = unsafe { ffi::mj_findFileVFS(vfs.as_ref(), c_name.as_ptr()) };
        let slot = usize::try_from(index)
            .map_err(|_| MujocoError::Vfs("file vanished from the VFS".into()))?;
        // SAFETY: mj_makeEmptyFileVFS allocated `size` (= xml.len()) bytes for this slot.
        unsafe {
            std::ptr::copy_nonoverlapping(xml.as_ptr(), vfs.filedata[slot].cast::<u8>(), xml.len());
        }
        let model = load(&c_name, vfs.as_ref(), name);
        // SAFETY: frees the buffers mj_makeEmptyFileVFS allocated, once.
        unsafe { ffi::mj_deleteVFS(vfs.as_mut()) };
        Self::with_model(model?)
    }

    fn with_model(model: NonNull<ffi::mjModel>) -> Result<Self, MujocoError> {
        // SAFETY: `model` is a valid compiled model.
        let data = unsafe { ffi::mj_makeData(model.as_ptr()) };
        let Some(data) = NonNull::new(data) else {
            // SAFETY: no Simulation owns the model yet: it is freed once, here.
            unsafe { ffi::mj_deleteModel(model.as_ptr()) };
            return Err(MujocoError::MakeData);
        };
        let simulation = Self { model, data };
        // SAFETY: model and data were just made for each other.
        unsafe { ffi::mj_forward(simulation.model.as_ptr(), simulation.data.as_ptr()) };
        Ok(simulation)
    }

    fn model(&self) -> &ffi::mjModel {
        // SAFETY: the model lives as long as `self` and is only read through this reference.
        unsafe { self.model.as_ref() }
    }

    fn data(&self) -> &ffi::mjData {
        // SAFETY: the data lives as long as `self`; writes go through `&mut self` methods only.
        unsafe { self.data.as_ref() }
    }

    /// Id of the named element, or `None` when the model has none of that name.
    pub fn id(&self, kind: ObjectKind, name: &str) -> Option<usize> {
        let c_name = CString::new(name).ok()?;
        // SAFETY: valid model; `c_name` is NUL-terminated.
        let id = unsafe { ffi::mj_name2id(self.model.as_ptr(), kind.raw(), c_name.as_ptr()) };
        usize::try_from(id).ok()
    }

    pub fn timestep(&self) -> f64 {
        self.model().opt.timestep
    }

    pub fn time(&self) -> f64 {
        self.data().time
    }

    pub fn step(&mut self) {
        // SAFETY: model and data belong together and `&mut self` makes the access exclusive.
        unsafe { ffi::mj_step(self.model.as_ptr(), self.data.as_ptr()) };
    }

    /// Recomputes positions, contacts and forces after the state was set directly.
    pub fn forward(&mut self) {
        // SAFETY: model and data belong together and `&mut self` makes the access exclusive.
        unsafe { ffi::mj_forward(self.model.as_ptr(), self.data.as_ptr()) };
    }

    /// Back to the model's initial state (qpos0, zero velocity, zero controls, time 0).
    pub fn reset(&mut self) {
        // SAFETY: model and data belong together and `&mut self` makes the access exclusive.
        unsafe { ffi::mj_resetData(self.model.as_ptr(), self.data.as_ptr()) };
    }

    pub fn joint_qpos_address(&self, joint: usize) -> usize {
        self.model_int(self.model().jnt_qposadr, self.model().njnt, joint)
    }

    pub fn joint_dof_address(&self, joint: usize) -> usize {
        self.model_int(self.model().jnt_dofadr, self.model().njnt, joint)
    }

    /// Position range of a joint, as the model declares it.
    pub fn joint_range(&self, joint: usize) -> (f64, f64) {
        let range = self.model_slice(self.model().jnt_range, 2 * self.model().njnt as usize);
        (range[2 * joint], range[2 * joint + 1])
    }

    pub fn qpos(&self) -> &[f64] {
        self.data_slice(self.data().qpos, self.model().nq as usize)
    }

    pub fn qpos_mut(&mut self) -> &mut [f64] {
        let len = self.model().nq as usize;
        // SAFETY: MuJoCo allocated nq doubles here for the life of the data; `&mut self` makes the borrow exclusive.
        unsafe { std::slice::from_raw_parts_mut(self.data().qpos, len) }
    }

    pub fn qvel(&self) -> &[f64] {
        self.data_slice(self.data().qvel, self.model().nv as usize)
    }

    pub fn qvel_mut(&mut self) -> &mut [f64] {
        let len = self.model().nv as usize;
        // SAFETY: MuJoCo allocated nv doubles here for the life of the data; `&mut self` makes the borrow exclusive.
        unsafe { std::slice::from_raw_parts_mut(self.data().qvel, len) }
    }

    pub fn ctrl_mut(&mut self) -> &mut [f64] {
        let len = self.model().nu as usize;
        // SAFETY: MuJoCo allocated nu doubles here for the life of the data; `&mut self` makes the borrow exclusive.
        unsafe { std::slice::from_raw_parts_mut(self.data().ctrl, len) }
    }

    /// Force of each actuator in actuation space (N m for the arm's hinge servos).
    pub fn actuator_force(&self) -> &[f64] {
        self.data_slice(self.data().actuator_force, self.model().nu as usize)
    }

    pub fn site_position(&self, site: usize) -> [f64; 3] {
        let all = self.data_slice(self.data().site_xpos, 3 * self.model().nsite as usize);
        [all[3 * site], all[3 * site + 1], all[3 * site + 2]]
    }

    /// Orientation of a site as a row-major 3x3 rotation matrix.
    pub fn site_rotation(&self, site: usize) -> [f64; 9] {
        let all = self.data_slice(self.data().site_xmat, 9 * self.model().nsite as usize);
        let mut rotation = [0.0; 9];
        rotation.copy_from_slice(&all[9 * site..9 * site + 9]);
        rotation
    }

    /// Orientation of a camera in the world as a row-major 3x3 rotation matrix (after a step or
    /// forward): its columns are the camera's axes.
    pub fn camera_rotation(&self, camera: usize) -> [f64; 9] {
        let all = self.data_slice(self.data().cam_xmat, 9 * self.model().ncam as usize);
        let mut rotation = [0.0; 9];
        rotation.copy_from_slice(&all[9 * camera..9 * camera + 9]);
        rotation
    }

    /// Half extents of a box site (its `size`).
    pub fn site_size(&self, site: usize) -> [f64; 3] {
        let all = self.model_slice(self.model().site_size, 3 * self.model().nsite as usize);
        [all[3 * site], all[3 * site + 1], all[3 * site + 2]]
    }

    pub fn geom_count(&self) -> usize {
        self.model().ngeom as usize
    }

    pub fn geom_body(&self, geom: usize) -> usize {
        self.model_int(self.model().geom_bodyid, self.model().ngeom, geom)
    }

    /// World position and orientation (w, x, y, z) of a body frame.
    pub fn body_pose(&self, body: usize) -> ([f64; 3], [f64; 4]) {
        let nbody = self.model().nbody as usize;
        let position = self.data_slice(self.data().xpos, 3 * nbody);
        let orientation = self.data_slice(self.data().xquat, 4 * nbody);
        (
            [
                position[3 * body],
                position[3 * body + 1],
                position[3 * body + 2],
            ],
            [
                orientation[4 * body],
                orientation[4 * body + 1],
                orientation[4 * body + 2],
                orientation[4 * body + 3],
            ],
        )
    }

    /// Pairs of geom ids in contact after the last step.
    pub fn contacts(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let count = self.data().ncon.max(0) as usize;
        let contacts = if count == 0 || self.data().contact.is_null() {
            &[][..]
        } else {
            // SAFETY: after a step or mj_forward the first `ncon` contacts of the array are valid.
            unsafe { std::slice::from_raw_parts(self.data().contact, count) }
        };
        contacts
            .iter()
            .map(|contact| (contact.geom1 as usize, contact.geom2 as usize))
    }

    /// Entry `index` of an integer model array of `len` entries; panics when out of range.
    fn model_int(&self, array: *const i32, len: i32, index: usize) -> usize {
        // SAFETY: callers pass a model array with the length MuJoCo allocated for it.
        let entries = unsafe { std::slice::from_raw_parts(array, len.max(0) as usize) };
        entries[index] as usize
    }

    fn model_slice(&self, array: *const f64, len: usize) -> &[f64] {
        // SAFETY: callers pass a model array with the length MuJoCo allocated for it.
        unsafe { std::slice::from_raw_parts(array, len) }
    }

    fn data_slice(&self, array: *const f64, len: usize) -> &[f64] {
        // SAFETY: callers pass a data array with the length MuJoCo allocated for it.
        unsafe { std::slice::from_raw_parts(array, len) }
    }
}

impl Drop for Simulation {
    fn drop(&mut self) {
        // SAFETY: both were made by MuJoCo for this value alone and are freed once.
        unsafe {
            ffi::mj_deleteData(self.data.as_ptr());
            ffi::mj_deleteModel(self.model.as_ptr());
        }
    }
}

fn load(
    name: &CStr,
    vfs: *const ffi::mjVFS,
    display: &str,
) -> Result<NonNull<ffi::mjModel>, MujocoError> {
    let mut error = [0 as c_char; 1024];
    let model =
        // SAFETY: `name` is NUL-terminated, `vfs` is NULL or valid, `error` is writable for its length.
        unsafe { ffi::mj_loadXML(name.as_ptr(), vfs, error.as_mut_ptr(), error.len() as i32) };
    NonNull::new(model).ok_or_else(|| MujocoError::Load {
        path: display.to_owned(),
        // SAFETY: mj_loadXML leaves a NUL-terminated message in `error`.
        message: unsafe { text_from_c(error.as_ptr()) },
    })
}
