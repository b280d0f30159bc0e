//! MuJoCo's own renderer, offscreen: scenes built from the simulation state on the physics thread,
//! and the GL-side context that draws them on the render thread. A GL context must be current on
//! the thread that makes and uses a [`RenderContext`] (crate::offscreen provides one).

use std::{marker::PhantomData, ptr::NonNull};

use super::{ffi, Simulation};
use crate::offscreen::GlContext;

/// What the cameras show: the model's visual groups, plus the collision geoms (group 3) when the
/// scene has no visual meshes (the lite variant would otherwise show no arm).
pub struct VisualOptions(ffi::mjvOption);

/// Geom group of the scene's primitive collision shapes (assets/so101_cube_to_bin.xml).
const COLLISION_GROUP: usize = 3;

impl VisualOptions {
    pub fn new(show_collision_geoms: bool) -> Self {
        let mut options = ffi::mjvOption::default();
        // SAFETY: `options` is a writable mjvOption.
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

// SAFETY: The scene is plain memory owned by this value; MuJoCo keeps no pointer to it elsewhere.
unsafe impl Send for SceneBuffer {}

/// Room for the geoms of one view (the scene has about 60; decorations add a few).
const MAX_SCENE_GEOMS: i32 = 2000;

impl SceneBuffer {
    pub fn new(sim: &Simulation, shadows: bool) -> Self {
        let mut scene: Box<ffi::mjvScene> = Box::default();
        // SAFETY: `scene` is a writable mjvScene and the model is valid.
        unsafe {
            ffi::mjv_defaultScene(scene.as_mut());
            ffi::mjv_makeScene(sim.model.as_ptr(), scene.as_mut(), MAX_SCENE_GEOMS);
        }
        scene.flags[ffi::mjRND_SHADOW as usize] = u8::from(shadows);
        Self { scene }
    }
}

/// The flags keying changes, and their values as mjv_defaultScene sets them.
const KEYING_FLAGS: [(u32, u8); 2] = [
    // The sky is the key sphere.
    (ffi::mjRND_SKYBOX, 1),
    (ffi::mjRND_HAZE, 1),
];

impl SceneBuffer {
    /// Paints the geoms `keyed` (by model geom id) in `key`, unlit in effect (emission saturates
    /// the key's channels, its zero channels stay zero: no texture, highlight or reflection), and
    /// encloses the view in a sphere of the key for the sky. For [`crate::cameras::backgrounds`];
    /// call after each [`Simulation::update_scene`], which rebuilds the geoms.
    pub fn key(&mut self, keyed: &[bool], key: [u8; 3], sky_radius: f64) {
        let rgba = [
            f32::from(key[0]) / 255.0,
            f32::from(key[1]) / 255.0,
            f32::from(key[2]) / 255.0,
            1.0,
        ];
        let scene = self.scene.as_mut();
        let count = scene.ngeom.max(0) as usize;
        // SAFETY: mjv_makeScene allocated maxgeom geoms, of which the first ngeom are set.
        let geoms = unsafe { std::slice::from_raw_parts_mut(scene.geoms, count) };
        for geom in geoms.iter_mut() {
            let is_keyed = geom.objtype == ffi::mjOBJ_GEOM as i32
                && usize::try_from(geom.objid)
                    .ok()
                    .and_then(|id| keyed.get(id))
                    .copied()
                    .unwrap_or(false);
            if is_keyed {
                paint(geom, rgba);
            }
        }
        if scene.ngeom < scene.maxgeom {
            // SAFETY: index ngeom < maxgeom lies within the allocation; mjv_initGeom fills it.
            let sky = unsafe { &mut *scene.geoms.add(count) };
            let centre = scene.camera[0].pos.map(f64::from);
            // Mirrored on one axis, its faces wind the other way: the inside is what back-face
            // culling keeps (culling stays on: off, the arm's meshes cost a quarter more).
            let size = [-sky_radius, sky_radius, sky_radius];
            // SAFETY: the pointers are to three- and nine-element arrays as MuJoCo reads them.
            unsafe {
                ffi::mjv_initGeom(
                    sky,
                    ffi::mjGEOM_SPHERE as i32,
                    size.as_ptr(),
                    centre.as_ptr(),
                    std::ptr::null(),
                    rgba.as_ptr(),
                );
            }
            sky.category = ffi::mjCAT_DECOR as i32;
            paint(sky, rgba);
            scene.ngeom += 1;
        }
        for (flag, _) in KEYING_FLAGS {
            scene.flags[flag as usize] = 0;
        }
    }

    /// Adds an upright cylinder to the view (seen by the camera only: not in the model, so no
    /// collision), lit like the scene's geoms. Call after [`Simulation::update_scene`] and before
    /// [`SceneBuffer::key`].
    pub fn add_cylinder(&mut self, centre: [f64; 3], radius: f64, half_height: f64, rgb: [f32; 3]) {
        let scene = self.scene.as_mut();
        if scene.ngeom >= scene.maxgeom {
            return;
        }
        let rgba = [rgb[0], rgb[1], rgb[2], 1.0];
        // mjv_initGeom reads a cylinder's size as a model geom's (radius, half height) and makes
        // the scaled (radius, radius, half height) itself.
        let size = [radius, half_height, 0.0];
        // SAFETY: index ngeom < maxgeom lies within the allocation; mjv_initGeom fills it from
        // three-element size and position arrays (a null matrix: upright).
        unsafe {
            let geom = &mut *scene.geoms.add(scene.ngeom as usize);
            ffi::mjv_initGeom(
                geom,
                ffi::mjGEOM_CYLINDER as i32,
                size.as_ptr(),
                centre.as_ptr(),
                std::ptr::null(),
                rgba.as_ptr(),
            );
            geom.category = ffi::mjCAT_DECOR as i32;
            geom.specular = 0.2;
        }
        scene.ngeom += 1;
    }

    /// Undoes [`SceneBuffer::key`]'s flags for a view without a background.
    pub fn unkey(&mut self) {
        for (flag, value) in KEYING_FLAGS {
            self.scene.flags[flag as usize] = value;
        }
    }
}

fn paint(geom: &mut ffi::mjvGeom, rgba: [f32; 4]) {
    geom.rgba = rgba;
    geom.emission = 1.0;
    geom.specular = 0.0;
    geom.shininess = 0.0;
    geom.reflectance = 0.0;
    geom.texid = -1;
}

impl Drop for SceneBuffer {
    fn drop(&mut self) {
        // SAFETY: made by mjv_makeScene, freed once.
        unsafe { ffi::mjv_freeScene(self.scene.as_mut()) };
    }
}

/// A private copy of the model for a renderer on another thread, its offscreen buffer sized for the
/// largest frame: the renderer reads it while the physics goes on, and the simulation's own model
/// is never touched.
pub struct RenderModel(NonNull<ffi::mjModel>);

// SAFETY: the copy is owned by this value alone; MuJoCo keeps no thread-local state for models.
unsafe impl Send for RenderModel {}

impl Drop for RenderModel {
    fn drop(&mut self) {
        // SAFETY: the model was made by mj_copyModel and is freed once, here.
        unsafe { ffi::mj_deleteModel(self.0.as_ptr()) };
    }
}

impl Simulation {
    /// Brings body, site and camera poses up to the current joint positions (mj_step leaves them
    /// at the state before its integration), so a frame shows the state it is stamped with.
    pub fn refresh_kinematics(&mut self) {
        let (model, data) = (self.model.as_ptr(), self.data.as_ptr());
        // SAFETY: model and data belong together and `&mut self` makes the access exclusive.
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
        // SAFETY: `view` is a writable mjvCamera.
        unsafe { ffi::mjv_defaultCamera(&mut view) };
        view.type_ = ffi::mjCAMERA_FIXED as i32;
        view.fixedcamid = camera as i32;
        // SAFETY: valid model and data; the scene buffer was made for this scene and the options initialised.
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

    /// How far the cameras see (the far clipping distance, m): the key sphere of
    /// [`SceneBuffer::key`] stays within it.
    pub fn view_distance(&self) -> f64 {
        let model = self.model();
        f64::from(model.vis.map.zfar) * model.stat.extent
    }

    /// Vertical field of view of a model camera, in degrees (MJCF `fovy`).
    pub fn camera_fovy(&self, camera: usize) -> f64 {
        let model = self.model();
        // SAFETY: cam_fovy holds ncam entries.
        let fovy = unsafe { std::slice::from_raw_parts(model.cam_fovy, model.ncam as usize) };
        fovy[camera]
    }

    /// A copy of the model for a renderer whose frames are at most `width` x `height` (the
    /// offscreen buffer grows to hold them; MJCF `<visual><global offwidth offheight>` otherwise).
    pub fn render_model(&self, width: u32, height: u32) -> RenderModel {
        // SAFETY: the model is valid; a NULL destination makes MuJoCo allocate the copy.
        let copy = unsafe { ffi::mj_copyModel(std::ptr::null_mut(), self.model.as_ptr()) };
        let Some(mut copy) = NonNull::new(copy) else {
            panic!("MuJoCo could not allocate a copy of the model");
        };
        // SAFETY: the copy is ours alone.
        let global = unsafe { &mut copy.as_mut().vis.global };
        global.offwidth = global.offwidth.max(width as i32);
        global.offheight = global.offheight.max(height as i32);
        RenderModel(copy)
    }
}

/// MuJoCo's GL resources (meshes, textures, the offscreen framebuffer) in the current GL context.
pub struct RenderContext<'gl> {
    context: Box<ffi::mjrContext>,
    _gl: PhantomData<&'gl GlContext>,
}

impl<'gl> RenderContext<'gl> {
    /// Uploads the model to `gl` (current on this thread, as a [`GlContext`] always is on the
    /// thread that owns it) and selects the offscreen framebuffer. The context borrows `gl`, so
    /// MuJoCo's GL resources go before their GL context does.
    pub fn new(_gl: &'gl GlContext, model: &RenderModel) -> Self {
        let mut context: Box<ffi::mjrContext> = Box::default();
        // SAFETY: a GL context is current on this thread (`gl` cannot leave the thread that made
        // it current) and the model copy is alive for the call.
        unsafe {
            ffi::mjr_defaultContext(context.as_mut());
            ffi::mjr_makeContext(
                model.0.as_ptr(),
                context.as_mut(),
                ffi::mjFONTSCALE_100 as i32,
            );
            ffi::mjr_setBuffer(ffi::mjFB_OFFSCREEN as i32, context.as_mut());
        }
        Self {
            context,
            _gl: PhantomData,
        }
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
        // SAFETY: the viewport lies within the offscreen buffer (asserted), `rgb` holds exactly its pixels, and the GL context is current on this thread (the context borrows the thread's GlContext).
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

impl Drop for RenderContext<'_> {
    fn drop(&mut self) {
        // SAFETY: made by mjr_makeContext, freed once while its GL context is still current (it outlives this value).
        unsafe { ffi::mjr_freeContext(self.context.as_mut()) };
    }
}
