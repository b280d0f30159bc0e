//! MuJoCo's own renderer, offscreen: scenes built from the simulation state on the physics thread,
//! and the GL-side context that draws them on the render thread. A GL context must be current on
//! the thread that makes and uses a [`RenderContext`] (crate::offscreen provides one).

use super::{ffi, Simulation};

/// What the cameras show: the model's visual groups, plus the collision geoms (group 3) when the
/// scene has no visual meshes (the lite variant would otherwise show no arm).
pub struct VisualOptions(ffi::mjvOption);

/// Geom group of the scene's primitive collision shapes (assets/so101_cube_to_bin.xml).
const COLLISION_GROUP: usize = 3;

impl VisualOptions {
    pub fn new(show_collision_geoms: bool) -> Self {
        let mut options = ffi::mjvOption::default();
        unsafe { ffi::mjv_defaultOption(&mut options) };
        options.geomgroup[COLLISION_GROUP] = u8::from(show_collision_geoms);
        Self(options)
    }
}

/// The geoms, lights and camera of one view, ready to draw. Built on the physics thread, drawn on
/// the render thread.
pub struct SceneBuffer {
    scene: Box<ffi::mjvScene>,
}

// The scene is plain memory owned by this value; MuJoCo keeps no pointer to it elsewhere.
unsafe impl Send for SceneBuffer {}

/// Room for the geoms of one view (the scene has about 60; decorations add a few).
const MAX_SCENE_GEOMS: i32 = 2000;

impl SceneBuffer {
    pub fn new(sim: &Simulation, shadows: bool) -> Self {
        let mut scene: Box<ffi::mjvScene> = Box::default();
        unsafe {
            ffi::mjv_defaultScene(scene.as_mut());
            ffi::mjv_makeScene(sim.model.as_ptr(), scene.as_mut(), MAX_SCENE_GEOMS);
        }
        scene.flags[ffi::mjRND_SHADOW as usize] = u8::from(shadows);
        Self { scene }
    }
}

impl Drop for SceneBuffer {
    fn drop(&mut self) {
        unsafe { ffi::mjv_freeScene(self.scene.as_mut()) };
    }
}

/// The model, to be read by [`RenderContext::new`] on another thread while the physics goes on
/// (MuJoCo never writes to a model while stepping). Valid as long as its [`Simulation`] lives.
pub struct ModelHandle(*const ffi::mjModel);

unsafe impl Send for ModelHandle {}

impl Simulation {
    /// Brings body, site and camera poses up to the current joint positions (mj_step leaves them
    /// at the state before its integration), so a frame shows the state it is stamped with.
    pub fn refresh_kinematics(&mut self) {
        let (model, data) = (self.model.as_ptr(), self.data.as_ptr());
        unsafe {
            ffi::mj_kinematics(model, data);
            ffi::mj_comPos(model, data);
            ffi::mj_camlight(model, data);
        }
    }

    /// Fills `scene` with the view of the model camera `camera`.
    pub fn update_scene(
        &mut self,
        scene: &mut SceneBuffer,
        camera: usize,
        options: &VisualOptions,
    ) {
        let mut view = ffi::mjvCamera::default();
        unsafe { ffi::mjv_defaultCamera(&mut view) };
        view.type_ = ffi::mjCAMERA_FIXED as i32;
        view.fixedcamid = camera as i32;
        unsafe {
            ffi::mjv_updateScene(
                self.model.as_ptr(),
                self.data.as_ptr(),
                &options.0,
                std::ptr::null(),
                &mut view,
                ffi::mjCAT_ALL as i32,
                scene.scene.as_mut(),
            );
        }
    }

    /// Vertical field of view of a model camera, in degrees (MJCF `fovy`).
    pub fn camera_fovy(&self, camera: usize) -> f64 {
        let model = self.model();
        let fovy = unsafe { std::slice::from_raw_parts(model.cam_fovy, model.ncam as usize) };
        fovy[camera]
    }

    /// Largest frame the offscreen buffer holds (MJCF `<visual><global offwidth offheight>`).
    pub fn offscreen_size(&self) -> (u32, u32) {
        let global = &self.model().vis.global;
        (
            global.offwidth.max(0) as u32,
            global.offheight.max(0) as u32,
        )
    }

    /// Resizes the offscreen buffer; takes effect in the next [`RenderContext`] made.
    pub fn set_offscreen_size(&mut self, width: u32, height: u32) {
        let global = unsafe { &mut self.model.as_mut().vis.global };
        global.offwidth = width as i32;
        global.offheight = height as i32;
    }

    pub fn model_handle(&self) -> ModelHandle {
        ModelHandle(self.model.as_ptr())
    }
}

/// MuJoCo's GL resources (meshes, textures, the offscreen framebuffer) in the current GL context.
pub struct RenderContext {
    context: Box<ffi::mjrContext>,
}

impl RenderContext {
    /// Uploads the model to the GL context current on this thread and selects the offscreen
    /// framebuffer.
    ///
    /// # Safety
    /// A GL context (2.0 or newer) must be current on this thread, and `model` must be alive for
    /// the duration of the call.
    pub unsafe fn new(model: &ModelHandle) -> Self {
        let mut context: Box<ffi::mjrContext> = Box::default();
        unsafe {
            ffi::mjr_defaultContext(context.as_mut());
            ffi::mjr_makeContext(model.0, context.as_mut(), ffi::mjFONTSCALE_100 as i32);
            ffi::mjr_setBuffer(ffi::mjFB_OFFSCREEN as i32, context.as_mut());
        }
        Self { context }
    }

    /// Size of the offscreen framebuffer actually created.
    pub fn size(&self) -> (u32, u32) {
        (
            self.context.offWidth.max(0) as u32,
            self.context.offHeight.max(0) as u32,
        )
    }

    /// Draws `scene` into the bottom-left `width` x `height` of the offscreen buffer and reads it
    /// into `rgb` (3 bytes a pixel, rows bottom-up as GL returns them).
    pub fn render(&mut self, scene: &mut SceneBuffer, width: u32, height: u32, rgb: &mut [u8]) {
        let (max_width, max_height) = self.size();
        assert!(
            width <= max_width && height <= max_height,
            "frame {width}x{height} larger than the offscreen buffer {max_width}x{max_height}"
        );
        assert_eq!(rgb.len(), 3 * width as usize * height as usize);
        let viewport = ffi::mjrRect {
            left: 0,
            bottom: 0,
            width: width as i32,
            height: height as i32,
        };
        unsafe {
            ffi::mjr_render(viewport, scene.scene.as_mut(), self.context.as_ref());
            ffi::mjr_readPixels(
                rgb.as_mut_ptr(),
                std::ptr::null_mut(),
                viewport,
                self.context.as_ref(),
            );
        }
    }
}

impl Drop for RenderContext {
    fn drop(&mut self) {
        unsafe { ffi::mjr_freeContext(self.context.as_mut()) };
    }
}
