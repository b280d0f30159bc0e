//! Puts a draw into the compiled model: colours, lights and cameras here; the cube's physics and
//! the servos through the world, which owns what depends on them.

use so101_core::contract::{CAMERAS_ON_THE_ARM, CAMERA_NAMES};

use super::draw::EpisodeDraw;
use crate::mujoco::{ObjectKind, Simulation};

/// Materials whose colour is randomized, by name in the scene.
const CUBE_MATERIAL: &str = "cube_mat";
const TABLE_MATERIAL: &str = "table_mat";
const BIN_MATERIAL: &str = "bin_mat";

/// The scene's elements a draw changes and their values as written, resolved once.
#[derive(Debug, Clone)]
pub struct SceneLook {
    materials: Vec<(usize, [f32; 4])>,
    lights: Vec<(usize, [f64; 3], [f32; 3])>,
    ambient: [f32; 3],
    cameras: Vec<(usize, [f64; 3], f64)>,
    /// Per camera of [`CAMERA_NAMES`] present in the scene: whether it rides the arm.
    on_arm: Vec<bool>,
}

impl SceneLook {
    /// Reads the nominal look; elements the scene lacks are left out.
    pub fn capture(sim: &Simulation) -> Self {
        let materials = [CUBE_MATERIAL, TABLE_MATERIAL, BIN_MATERIAL]
            .iter()
            .map(|name| {
                sim.id(ObjectKind::Material, name)
                    .map(|id| (id, sim.material_rgba(id)))
                    .unwrap_or((usize::MAX, [0.0; 4]))
            })
            .collect();
        let lights = (0..sim.light_count())
            .map(|id| {
                let (direction, diffuse) = sim.light(id);
                (id, direction, diffuse)
            })
            .collect();
        let mut cameras = Vec::new();
        let mut on_arm = Vec::new();
        for name in CAMERA_NAMES {
            if let Some(id) = sim.id(ObjectKind::Camera, name) {
                let (position, fovy) = sim.camera_pose(id);
                cameras.push((id, position, fovy));
                on_arm.push(CAMERAS_ON_THE_ARM.contains(&name));
            }
        }
        Self {
            materials,
            lights,
            ambient: sim.headlight_ambient(),
            cameras,
            on_arm,
        }
    }

    pub fn light_count(&self) -> usize {
        self.lights.len()
    }

    pub fn cameras_on_arm(&self) -> &[bool] {
        &self.on_arm
    }

    /// The nominal look with the draw's changes (a draw made for this scene's lights and cameras).
    pub fn apply(&self, sim: &mut Simulation, draw: &EpisodeDraw) {
        let offsets = [
            draw.cube_colour_offset,
            draw.table_colour_offset,
            draw.bin_colour_offset,
        ];
        for ((id, rgba), offset) in self.materials.iter().zip(offsets) {
            if *id != usize::MAX {
                let mut colour = *rgba;
                for channel in 0..3 {
                    colour[channel] = (colour[channel] + offset[channel]).clamp(0.0, 1.0);
                }
                sim.set_material_rgba(*id, colour);
            }
        }
        for ((id, direction, diffuse), light) in self.lights.iter().zip(&draw.lights) {
            let moved: [f64; 3] =
                std::array::from_fn(|axis| direction[axis] + light.direction_offset[axis]);
            let norm = moved.iter().map(|value| value * value).sum::<f64>().sqrt();
            let direction = if norm > 1e-6 {
                moved.map(|value| value / norm)
            } else {
                *direction
            };
            let scale = light.intensity_scale as f32;
            sim.set_light(*id, direction, diffuse.map(|value| value * scale));
        }
        let _ = self.ambient;
        sim.set_headlight_ambient([draw.ambient; 3]);
        for ((id, position, fovy), camera) in self.cameras.iter().zip(&draw.cameras) {
            let moved = std::array::from_fn(|axis| position[axis] + camera.position_offset[axis]);
            sim.set_camera_pose(*id, moved, (fovy + camera.fovy_offset).clamp(10.0, 170.0));
        }
    }

    /// Back to the scene as written.
    pub fn restore(&self, sim: &mut Simulation) {
        for (id, rgba) in &self.materials {
            if *id != usize::MAX {
                sim.set_material_rgba(*id, *rgba);
            }
        }
        for (id, direction, diffuse) in &self.lights {
            sim.set_light(*id, *direction, *diffuse);
        }
        sim.set_headlight_ambient(self.ambient);
        for (id, position, fovy) in &self.cameras {
            sim.set_camera_pose(*id, *position, *fovy);
        }
    }
}
