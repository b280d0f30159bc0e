//! Cameras of an in-process world: so101_sim's camera rig, its frames delivered to a mailbox the
//! world reads after asking for them (rendered on the rig's own thread, with the GIL released).

use std::sync::mpsc::{self, Receiver};

use numpy::{PyArray1, PyArrayMethods};
use pyo3::{
    exceptions::{PyRuntimeError, PyValueError},
    prelude::*,
    types::PyDict,
};
use so101_sim::{
    cameras::{
        rig::{CameraRig, Capture, FrameBatch, RigOptions},
        spec::{CameraSpec, FrameSize, MAX_SIDE},
    },
    env::TaskEnv,
    offscreen::RendererChoice,
};

/// {camera: uint8[height, width, 3]}.
pub type Frames<'py> = Bound<'py, PyDict>;

pub struct CameraSet {
    rig: CameraRig,
    frames: Receiver<FrameBatch>,
    /// (name, height, width) in the rig's order.
    cameras: Vec<(String, u32, u32)>,
}

fn renderer_choice(name: &str) -> PyResult<RendererChoice> {
    match name {
        "auto" => Ok(RendererChoice::Auto),
        "egl" => Ok(RendererChoice::Egl),
        "osmesa" => Ok(RendererChoice::Osmesa),
        other => Err(PyValueError::new_err(format!(
            "renderer {other:?}: auto, egl or osmesa"
        ))),
    }
}

impl CameraSet {
    pub fn start(
        env: &TaskEnv,
        cameras: &[(String, (u32, u32))],
        renderer: &str,
        shadows: bool,
    ) -> PyResult<Self> {
        if cameras.is_empty() {
            return Err(PyValueError::new_err("no cameras named"));
        }
        let mut specs = Vec::with_capacity(cameras.len());
        for (name, (height, width)) in cameras {
            if *width == 0 || *height == 0 || *width > MAX_SIDE || *height > MAX_SIDE {
                return Err(PyValueError::new_err(format!(
                    "camera {name}: {width}x{height} is not a frame size from 1x1 to \
                     {MAX_SIDE}x{MAX_SIDE}"
                )));
            }
            specs.push(CameraSpec {
                name: name.clone(),
                size: FrameSize {
                    width: *width,
                    height: *height,
                },
                // Any rate: every render call restarts the clocks, so each camera is due then.
                rate: 30.0,
            });
        }
        let options = RigOptions {
            renderer: renderer_choice(renderer)?,
            show_collision_geoms: true,
            shadows,
            wait_for_renderer: true,
            backgrounds: env.backgrounds().map(ToOwned::to_owned),
        };
        let (mailbox, frames) = mpsc::sync_channel(1);
        let rig = CameraRig::start(
            env.world().simulation(),
            specs,
            options,
            env.world().time(),
            move |batches| {
                for batch in batches {
                    if mailbox.send(batch).is_err() {
                        break;
                    }
                }
            },
        )
        .map_err(|error| PyRuntimeError::new_err(format!("{error:#}")))?;
        Ok(Self {
            rig,
            frames,
            cameras: cameras
                .iter()
                .map(|(name, (height, width))| (name.clone(), *height, *width))
                .collect(),
        })
    }

    /// Every camera takes its next frame at the next capture.
    pub fn restart(&mut self, time: f64) {
        self.rig.restart(time);
    }

    /// Renders every camera at the world's current state and waits for the frames.
    pub fn capture(&mut self, env: &mut TaskEnv) -> PyResult<FrameBatch> {
        self.request(env)?;
        self.receive()
    }

    /// Hands every camera's view of the world's current state to the render thread.
    pub fn request(&mut self, env: &mut TaskEnv) -> PyResult<()> {
        let time = env.world().time();
        self.rig.restart(time);
        let extras = env.view_extras();
        match self
            .rig
            .capture_and_wait(env.world_mut().simulation_mut(), time, extras)
        {
            Capture::Queued(_) => Ok(()),
            Capture::Nothing | Capture::Skipped => {
                Err(PyRuntimeError::new_err("the camera render thread ended"))
            }
        }
    }

    /// The frames of the last request.
    pub fn receive(&self) -> PyResult<FrameBatch> {
        self.frames
            .recv()
            .map_err(|_| PyRuntimeError::new_err("the camera render thread ended"))
    }

    pub fn to_python<'py>(&self, py: Python<'py>, batch: FrameBatch) -> PyResult<Frames<'py>> {
        let frames = PyDict::new(py);
        for frame in batch.frames {
            let (name, height, width) = &self.cameras[frame.camera];
            let image = PyArray1::from_vec(py, frame.rgb).reshape([
                *height as usize,
                *width as usize,
                3,
            ])?;
            frames.set_item(name, image)?;
        }
        Ok(frames)
    }
}
