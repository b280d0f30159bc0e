//! Writing into the compiled model: what the servo model and domain randomization change between
//! episodes (actuator gains, joint friction, masses, sizes, colours, lights, cameras). MuJoCo
//! reads these arrays at every step, so a change takes effect at the next one.

use super::{ffi, Simulation};

impl Simulation {
    /// Makes an actuator a direct torque source: force = ctrl (N m), unclipped by its control
    /// range; its force range still applies.
    pub fn set_actuator_direct(&mut self, actuator: usize) {
        let nu = self.model().nu as usize;
        let gain = self.model_slice_mut(self.model().actuator_gainprm, nu * ffi::mjNGAIN as usize);
        let row =
            &mut gain[actuator * ffi::mjNGAIN as usize..(actuator + 1) * ffi::mjNGAIN as usize];
        row.fill(0.0);
        row[0] = 1.0;
        let bias = self.model_slice_mut(self.model().actuator_biasprm, nu * ffi::mjNBIAS as usize);
        bias[actuator * ffi::mjNBIAS as usize..(actuator + 1) * ffi::mjNBIAS as usize].fill(0.0);
        // SAFETY: MuJoCo allocated nu bytes here for the life of the model; `&mut self` is exclusive.
        let limited =
            unsafe { std::slice::from_raw_parts_mut(self.model().actuator_ctrllimited, nu) };
        limited[actuator] = 0;
    }

    /// Sets an actuator's force range (N m), symmetric.
    pub fn set_actuator_force_limit(&mut self, actuator: usize, limit: f64) {
        let nu = self.model().nu as usize;
        let range = self.model_slice_mut(self.model().actuator_forcerange, 2 * nu);
        range[2 * actuator] = -limit;
        range[2 * actuator + 1] = limit;
    }

    /// A degree of freedom's damping (N m s/rad), dry friction (N m) and armature (kg m²).
    pub fn set_dof_friction(&mut self, dof: usize, damping: f64, friction: f64, armature: f64) {
        let nv = self.model().nv as usize;
        self.model_slice_mut(self.model().dof_damping, nv)[dof] = damping;
        self.model_slice_mut(self.model().dof_frictionloss, nv)[dof] = friction;
        self.model_slice_mut(self.model().dof_armature, nv)[dof] = armature;
    }

    pub fn dof_friction(&self, dof: usize) -> (f64, f64, f64) {
        let nv = self.model().nv as usize;
        (
            self.model_slice(self.model().dof_damping, nv)[dof],
            self.model_slice(self.model().dof_frictionloss, nv)[dof],
            self.model_slice(self.model().dof_armature, nv)[dof],
        )
    }

    /// A geom's size parameters (a box's half extents).
    pub fn geom_size(&self, geom: usize) -> [f64; 3] {
        let all = self.model_slice(self.model().geom_size, 3 * self.model().ngeom as usize);
        [all[3 * geom], all[3 * geom + 1], all[3 * geom + 2]]
    }

    pub fn set_geom_size(&mut self, geom: usize, size: [f64; 3]) {
        let ngeom = self.model().ngeom as usize;
        self.model_slice_mut(self.model().geom_size, 3 * ngeom)[3 * geom..3 * geom + 3]
            .copy_from_slice(&size);
        // The broad phase bounds the geom by its bounding-sphere radius.
        let radius = size.iter().map(|half| half * half).sum::<f64>().sqrt();
        self.model_slice_mut(self.model().geom_rbound, ngeom)[geom] = radius;
    }

    /// Puts a geom in a visual group: the views draw groups 0-2 (and 3 in the lite variant), not
    /// 4 and 5.
    pub fn set_geom_group(&mut self, geom: usize, group: i32) {
        let ngeom = self.model().ngeom as usize;
        // SAFETY: MuJoCo allocated ngeom ints here for the life of the model; `&mut self` is
        // exclusive.
        let groups = unsafe { std::slice::from_raw_parts_mut(self.model().geom_group, ngeom) };
        groups[geom] = group;
    }

    /// A geom's sliding, torsional and rolling friction.
    pub fn geom_friction(&self, geom: usize) -> [f64; 3] {
        let all = self.model_slice(self.model().geom_friction, 3 * self.model().ngeom as usize);
        [all[3 * geom], all[3 * geom + 1], all[3 * geom + 2]]
    }

    pub fn set_geom_friction(&mut self, geom: usize, friction: [f64; 3]) {
        let ngeom = self.model().ngeom as usize;
        self.model_slice_mut(self.model().geom_friction, 3 * ngeom)[3 * geom..3 * geom + 3]
            .copy_from_slice(&friction);
    }

    /// A body's mass (kg) and diagonal inertia (kg m²).
    pub fn body_mass(&self, body: usize) -> (f64, [f64; 3]) {
        let nbody = self.model().nbody as usize;
        let inertia = self.model_slice(self.model().body_inertia, 3 * nbody);
        (
            self.model_slice(self.model().body_mass, nbody)[body],
            [
                inertia[3 * body],
                inertia[3 * body + 1],
                inertia[3 * body + 2],
            ],
        )
    }

    pub fn set_body_mass(&mut self, body: usize, mass: f64, inertia: [f64; 3]) {
        let nbody = self.model().nbody as usize;
        self.model_slice_mut(self.model().body_mass, nbody)[body] = mass;
        self.model_slice_mut(self.model().body_inertia, 3 * nbody)[3 * body..3 * body + 3]
            .copy_from_slice(&inertia);
    }

    /// A material's colour (r, g, b, a).
    pub fn material_rgba(&self, material: usize) -> [f32; 4] {
        let all = self.model_f32(self.model().mat_rgba, 4 * self.model().nmat as usize);
        [
            all[4 * material],
            all[4 * material + 1],
            all[4 * material + 2],
            all[4 * material + 3],
        ]
    }

    pub fn set_material_rgba(&mut self, material: usize, rgba: [f32; 4]) {
        let nmat = self.model().nmat as usize;
        // SAFETY: MuJoCo allocated 4 nmat floats here for the life of the model; `&mut self` is exclusive.
        let all = unsafe { std::slice::from_raw_parts_mut(self.model().mat_rgba, 4 * nmat) };
        all[4 * material..4 * material + 4].copy_from_slice(&rgba);
    }

    pub fn light_count(&self) -> usize {
        self.model().nlight.max(0) as usize
    }

    /// A light's direction (unit vector, model frame) and diffuse colour.
    pub fn light(&self, light: usize) -> ([f64; 3], [f32; 3]) {
        let nlight = self.model().nlight as usize;
        let dir = self.model_slice(self.model().light_dir, 3 * nlight);
        let diffuse = self.model_f32(self.model().light_diffuse, 3 * nlight);
        (
            [dir[3 * light], dir[3 * light + 1], dir[3 * light + 2]],
            [
                diffuse[3 * light],
                diffuse[3 * light + 1],
                diffuse[3 * light + 2],
            ],
        )
    }

    pub fn set_light(&mut self, light: usize, direction: [f64; 3], diffuse: [f32; 3]) {
        let nlight = self.model().nlight as usize;
        for array in [self.model().light_dir, self.model().light_dir0] {
            self.model_slice_mut(array, 3 * nlight)[3 * light..3 * light + 3]
                .copy_from_slice(&direction);
        }
        // SAFETY: MuJoCo allocated 3 nlight floats here for the life of the model; `&mut self` is exclusive.
        let all = unsafe { std::slice::from_raw_parts_mut(self.model().light_diffuse, 3 * nlight) };
        all[3 * light..3 * light + 3].copy_from_slice(&diffuse);
    }

    /// The headlight's ambient colour (what lights every surface from no direction).
    pub fn headlight_ambient(&self) -> [f32; 3] {
        self.model().vis.headlight.ambient
    }

    pub fn set_headlight_ambient(&mut self, ambient: [f32; 3]) {
        // SAFETY: the model lives as long as `self`; `&mut self` makes the write exclusive.
        unsafe { self.model.as_mut().vis.headlight.ambient = ambient };
    }

    /// A camera's position in its body's frame and its vertical field of view (degrees).
    pub fn camera_pose(&self, camera: usize) -> ([f64; 3], f64) {
        let ncam = self.model().ncam as usize;
        let pos = self.model_slice(self.model().cam_pos, 3 * ncam);
        (
            [pos[3 * camera], pos[3 * camera + 1], pos[3 * camera + 2]],
            self.model_slice(self.model().cam_fovy, ncam)[camera],
        )
    }

    pub fn set_camera_pose(&mut self, camera: usize, position: [f64; 3], fovy: f64) {
        let ncam = self.model().ncam as usize;
        self.model_slice_mut(self.model().cam_pos, 3 * ncam)[3 * camera..3 * camera + 3]
            .copy_from_slice(&position);
        self.model_slice_mut(self.model().cam_fovy, ncam)[camera] = fovy;
    }

    /// The body a camera is attached to (0: the world).
    pub fn camera_body(&self, camera: usize) -> usize {
        self.model_int(self.model().cam_bodyid, self.model().ncam, camera)
    }

    /// Puts a camera at `position` with `orientation` (w, x, y, z) in its body's frame, with a
    /// vertical field of view of `fovy` degrees.
    pub fn set_camera_frame(
        &mut self,
        camera: usize,
        position: [f64; 3],
        orientation: [f64; 4],
        fovy: f64,
    ) {
        let ncam = self.model().ncam as usize;
        self.model_slice_mut(self.model().cam_quat, 4 * ncam)[4 * camera..4 * camera + 4]
            .copy_from_slice(&orientation);
        self.set_camera_pose(camera, position, fovy);
    }

    /// The joint-space inertia seen at a degree of freedom in the current pose (the mass matrix's
    /// diagonal, armature included), kg m².
    pub fn dof_inertia(&self, dof: usize) -> f64 {
        let nv = self.model().nv as usize;
        // SAFETY: dof_Madr has nv entries for the life of the model.
        let address = unsafe { std::slice::from_raw_parts(self.model().dof_Madr, nv) }[dof];
        let nm = self.model().nM as usize;
        self.data_slice(self.data().qM, nm)[address as usize]
    }

    /// Gravity, Coriolis and centrifugal torque at a degree of freedom (N m; gravity alone at
    /// rest), as of the last forward pass.
    pub fn dof_bias(&self, dof: usize) -> f64 {
        self.data_slice(self.data().qfrc_bias, self.model().nv as usize)[dof]
    }

    fn model_slice_mut(&mut self, array: *mut f64, len: usize) -> &mut [f64] {
        // SAFETY: callers pass a model array with the length MuJoCo allocated for it; `&mut self`
        // makes the borrow exclusive.
        unsafe { std::slice::from_raw_parts_mut(array, len) }
    }

    fn model_f32(&self, array: *const f32, len: usize) -> &[f32] {
        // SAFETY: callers pass a model array with the length MuJoCo allocated for it.
        unsafe { std::slice::from_raw_parts(array, len) }
    }
}
