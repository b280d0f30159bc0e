//! The camera rig: the physics thread builds the views of the cameras that are due, a render
//! thread (owning the GL context) draws them, and a consumer thread the rig's owner supplies
//! (the sim node's publisher, a Python world's frame mailbox) takes the finished frames.
//!
//! Rendering never holds the physics back in real time: the physics hands a frame over only when
//! the renderer has a free set of views, and otherwise skips (and counts) it. In lockstep and
//! `--speed` modes it waits for a free set instead, so every frame is rendered at its sim-time
//! instant.

use std::{
    path::PathBuf,
    sync::{
        mpsc::{self, Receiver, SyncSender},
        Arc, Mutex,
    },
    thread::JoinHandle,
    time::Instant,
};

use anyhow::{bail, Context, Result};
use so101_core::contract::CAMERAS_ON_THE_ARM;

use super::{
    backgrounds::{self, Backgrounds},
    intrinsics::Intrinsics,
    schedule::FrameClock,
    spec::CameraSpec,
};
use crate::{
    mujoco::{
        render::{RenderContext, RenderModel, SceneBuffer, VisualOptions},
        ObjectKind, Simulation,
    },
    offscreen::{GlContext, RendererChoice},
    scene,
};

/// One rendered frame, rows top-down, RGB.
pub struct RenderedFrame {
    /// Index of the camera in the rig's list.
    pub camera: usize,
    pub rgb: Vec<u8>,
}

/// Frames of one sim-time instant.
pub struct FrameBatch {
    pub sim_time: f64,
    pub frames: Vec<RenderedFrame>,
    /// Signalled by the consumer once it is done with the frames (the sim node answers a
    /// lockstep /sim/step only after they are on the wire).
    pub published: Option<SyncSender<()>>,
}

/// How the rig is set up besides its cameras.
#[derive(Debug, Clone)]
pub struct RigOptions {
    pub renderer: RendererChoice,
    /// Shows the collision geoms (the lite scene has no visual meshes).
    pub show_collision_geoms: bool,
    pub shadows: bool,
    /// Wait for the renderer rather than skip frames (every mode but real time).
    pub wait_for_renderer: bool,
    /// Real backgrounds behind the scene (the randomization's `backgrounds`): a folder of
    /// pictures per fixed camera; the episode's draw picks one.
    pub backgrounds: Option<PathBuf>,
}

/// What the views show beyond the model: the episode's draws that only the cameras see.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ViewExtras {
    /// The draw of real backgrounds, for a rig that has them (none: the sim's own scenery).
    pub background: Option<u64>,
    /// An object on the table, in every camera's view.
    pub distractor: Option<Cylinder>,
    /// A task's mark on the table (push_cube's target), in every camera's view.
    pub mark: Option<Cylinder>,
}

/// An upright cylinder the cameras see (no collision).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cylinder {
    pub centre: [f64; 3],
    pub radius: f64,
    pub half_height: f64,
    pub rgb: [f32; 3],
}

/// Counters of one camera.
#[derive(Debug, Clone, Default)]
pub struct CameraCounters {
    pub name: String,
    pub rendered: u64,
    pub skipped: u64,
}

/// What /diagnostics reports about the cameras.
#[derive(Debug, Clone, Default)]
pub struct RigDiagnostics {
    pub renderer: String,
    pub cameras: Vec<CameraCounters>,
    /// Mean wall time to draw and read one frame.
    pub mean_render_ms: f64,
}

/// The per-camera views handed to the render thread and back.
struct Views(Vec<SceneBuffer>);

struct RenderJob {
    sim_time: f64,
    views: Views,
    due: Vec<usize>,
    /// The episode's draw of backgrounds, for the views keyed with it.
    background: Option<u64>,
    published: Option<SyncSender<()>>,
}

/// What the physics thread needs to key a view for a background.
struct Keying {
    /// By model geom id: whether it is scenery, replaced by the background.
    scenery: Vec<bool>,
    sky_radius: f64,
    /// By camera: whether it shows a background (a fixed camera).
    shows: Vec<bool>,
}

struct Camera {
    spec: CameraSpec,
    model_id: usize,
    clock: FrameClock,
    skipped: u64,
}

#[derive(Default)]
struct RenderTotals {
    rendered: Vec<u64>,
    frames: u64,
    seconds: f64,
}

pub struct CameraRig {
    cameras: Vec<Camera>,
    options: VisualOptions,
    keying: Option<Keying>,
    wait_for_renderer: bool,
    free: Vec<Views>,
    returned: Receiver<Views>,
    jobs: Option<SyncSender<RenderJob>>,
    totals: Arc<Mutex<RenderTotals>>,
    renderer: String,
    render_thread: Option<JoinHandle<()>>,
    consumer_thread: Option<JoinHandle<()>>,
}

/// Frames queued between the render and the consumer thread: beyond it rendering waits, and so,
/// through the views, does the physics (or it skips frames in real time).
const PUBLISH_QUEUE: usize = 2;

/// Outcome of [`CameraRig::capture`].
pub enum Capture {
    /// No camera was due.
    Nothing,
    /// Handed to the renderer; the receiver (when asked for) fires once the frames are published.
    Queued(Option<Receiver<()>>),
    /// The renderer was busy (real time): the frames were skipped.
    Skipped,
}

impl Capture {
    /// What fires once the frames are published, if any were queued with a notice.
    pub fn published(self) -> Option<Receiver<()>> {
        match self {
            Self::Queued(published) => published,
            Self::Nothing | Self::Skipped => None,
        }
    }
}

impl CameraRig {
    /// The pinhole model of each camera of `specs`; an error names a camera the scene lacks.
    pub fn intrinsics(sim: &Simulation, specs: &[CameraSpec]) -> Result<Vec<Intrinsics>> {
        Ok(model_ids(sim, specs)?
            .into_iter()
            .zip(specs)
            .map(|(model_id, spec)| {
                Intrinsics::from_fovy(sim.camera_fovy(model_id), spec.size.width, spec.size.height)
            })
            .collect())
    }

    /// Checks the cameras against the model, starts `consume` on a thread of its own with the
    /// queue of finished frames (it ends when the queue closes), and starts the render thread
    /// (which makes the GL context and uploads the model before this returns).
    pub fn start(
        sim: &Simulation,
        specs: Vec<CameraSpec>,
        rig: RigOptions,
        start_time: f64,
        consume: impl FnOnce(Receiver<FrameBatch>) + Send + 'static,
    ) -> Result<Self> {
        let model_ids = model_ids(sim, &specs)?;
        let cameras: Vec<Camera> = specs
            .into_iter()
            .zip(model_ids)
            .map(|(spec, model_id)| Camera {
                clock: FrameClock::new(spec.rate, start_time, sim.timestep()),
                spec,
                model_id,
                skipped: 0,
            })
            .collect();
        // The renderer's offscreen buffer must hold the largest frame.
        let (mut width, mut height) = (1, 1);
        for camera in &cameras {
            width = width.max(camera.spec.size.width);
            height = height.max(camera.spec.size.height);
        }
        let model = sim.render_model(width, height);
        let backgrounds = match &rig.backgrounds {
            Some(dir) => {
                let cameras: Vec<(String, bool)> = cameras
                    .iter()
                    .map(|camera| {
                        let name = camera.spec.name.as_str();
                        (name.to_owned(), !CAMERAS_ON_THE_ARM.contains(&name))
                    })
                    .collect();
                Some(Arc::new(Backgrounds::load(dir, &cameras)?))
            }
            None => None,
        };
        let keying = backgrounds.as_ref().map(|backgrounds| Keying {
            scenery: scene::background_geoms(sim),
            sky_radius: 0.5 * sim.view_distance(),
            shows: (0..cameras.len())
                .map(|camera| backgrounds.shows(camera))
                .collect(),
        });

        let (batch_sender, batches) = mpsc::sync_channel::<FrameBatch>(PUBLISH_QUEUE);
        let consumer_thread = std::thread::Builder::new()
            .name("camera-consumer".into())
            .spawn(move || consume(batches))
            .context("cannot start the camera consumer thread")?;

        // Two sets of views let the physics build the next frame while one renders; real time
        // keeps one, so a frame is never older than one render when it goes out.
        let sets = if rig.wait_for_renderer { 2 } else { 1 };
        let free: Vec<Views> = (0..sets)
            .map(|_| {
                Views(
                    cameras
                        .iter()
                        .map(|_| SceneBuffer::new(sim, rig.shadows))
                        .collect(),
                )
            })
            .collect();
        let sizes: Vec<(u32, u32)> = cameras
            .iter()
            .map(|camera| (camera.spec.size.width, camera.spec.size.height))
            .collect();
        let totals = Arc::new(Mutex::new(RenderTotals {
            rendered: vec![0; cameras.len()],
            ..RenderTotals::default()
        }));
        let (job_sender, jobs) = mpsc::sync_channel::<RenderJob>(sets);
        let (return_sender, returned) = mpsc::channel::<Views>();
        let (ready_sender, ready) = mpsc::channel::<Result<String, String>>();
        let thread_totals = Arc::clone(&totals);
        let renderer_choice = rig.renderer;
        let render_thread = std::thread::Builder::new()
            .name("camera-render".into())
            .spawn(move || {
                render_thread(RenderThread {
                    choice: renderer_choice,
                    model,
                    size: (width, height),
                    sizes,
                    backgrounds,
                    jobs,
                    returns: return_sender,
                    batches: batch_sender,
                    totals: thread_totals,
                    ready: ready_sender,
                })
            })
            .context("cannot start the camera render thread")?;
        let renderer = match ready.recv() {
            Ok(Ok(description)) => description,
            Ok(Err(error)) => {
                let _ = render_thread.join();
                bail!("{error} (--cameras none runs without rendering)");
            }
            Err(_) => bail!("the camera render thread died while starting"),
        };
        tracing::info!(
            renderer = %renderer,
            cameras = %cameras
                .iter()
                .map(|camera| format!("{}:{}@{}", camera.spec.name, camera.spec.size, camera.spec.rate))
                .collect::<Vec<_>>()
                .join(","),
            "cameras ready"
        );
        Ok(Self {
            cameras,
            options: VisualOptions::new(rig.show_collision_geoms),
            keying,
            wait_for_renderer: rig.wait_for_renderer,
            free,
            returned,
            jobs: Some(job_sender),
            totals,
            renderer,
            render_thread: Some(render_thread),
            consumer_thread: Some(consumer_thread),
        })
    }

    /// Every camera renders at `rate` frames per second of sim time from now on.
    pub fn set_rate(&mut self, rate: f64) {
        for camera in &mut self.cameras {
            camera.spec.rate = rate;
            camera.clock.set_rate(rate);
        }
    }

    /// Every camera takes a frame at the next capture (a new episode).
    pub fn restart(&mut self, time: f64) {
        for camera in &mut self.cameras {
            camera.clock.restart(time);
        }
    }

    /// Renders the cameras due at `time` from the simulation's current state (its kinematics
    /// up to date, as World::advance leaves them), with the episode's `extras` (the
    /// randomization's background and distractor). With `notify` (and a rig that waits for its
    /// renderer), the returned receiver fires once those frames are published.
    pub fn capture(
        &mut self,
        sim: &mut Simulation,
        time: f64,
        extras: ViewExtras,
        notify: bool,
    ) -> Capture {
        self.capture_with(
            sim,
            time,
            extras,
            self.wait_for_renderer,
            notify && self.wait_for_renderer,
        )
    }

    /// Like [`CameraRig::capture`], but waits for the renderer in every mode and always notifies:
    /// for the first frames, which also warm the renderer up (its first draw compiles shaders).
    pub fn capture_and_wait(
        &mut self,
        sim: &mut Simulation,
        time: f64,
        extras: ViewExtras,
    ) -> Capture {
        self.capture_with(sim, time, extras, true, true)
    }

    fn capture_with(
        &mut self,
        sim: &mut Simulation,
        time: f64,
        extras: ViewExtras,
        wait: bool,
        notify: bool,
    ) -> Capture {
        let due: Vec<usize> = (0..self.cameras.len())
            .filter(|&index| self.cameras[index].clock.take_due(time))
            .collect();
        if due.is_empty() {
            return Capture::Nothing;
        }
        self.free.extend(self.returned.try_iter());
        if self.free.is_empty() && wait {
            if let Ok(views) = self.returned.recv() {
                self.free.push(views);
            }
        }
        let Some(mut views) = self.free.pop() else {
            for &index in &due {
                self.cameras[index].skipped += 1;
            }
            return Capture::Skipped;
        };
        let background = extras.background.filter(|_| self.keying.is_some());
        for &index in &due {
            let view = &mut views.0[index];
            sim.update_scene(view, self.cameras[index].model_id, &self.options);
            for cylinder in [extras.mark, extras.distractor].into_iter().flatten() {
                view.add_cylinder(
                    cylinder.centre,
                    cylinder.radius,
                    cylinder.half_height,
                    cylinder.rgb,
                );
            }
            match (&self.keying, background) {
                (Some(keying), Some(_)) if keying.shows[index] => {
                    view.key(&keying.scenery, backgrounds::KEY, keying.sky_radius);
                }
                _ => view.unkey(),
            }
        }
        let (published, receiver) = if notify {
            let (sender, receiver) = mpsc::sync_channel(1);
            (Some(sender), Some(receiver))
        } else {
            (None, None)
        };
        let job = RenderJob {
            sim_time: time,
            views,
            due,
            background,
            published,
        };
        match &self.jobs {
            Some(jobs) if jobs.send(job).is_ok() => Capture::Queued(receiver),
            _ => {
                if self.jobs.take().is_some() {
                    tracing::error!("the camera render thread ended: no more camera frames");
                }
                Capture::Skipped
            }
        }
    }

    pub fn diagnostics(&self) -> RigDiagnostics {
        let totals = self.totals.lock().map(|totals| {
            (
                totals.rendered.clone(),
                if totals.frames == 0 {
                    0.0
                } else {
                    1e3 * totals.seconds / totals.frames as f64
                },
            )
        });
        let (rendered, mean_render_ms) = totals.unwrap_or_default();
        RigDiagnostics {
            renderer: self.renderer.clone(),
            cameras: self
                .cameras
                .iter()
                .enumerate()
                .map(|(index, camera)| CameraCounters {
                    name: camera.spec.name.clone(),
                    rendered: rendered.get(index).copied().unwrap_or(0),
                    skipped: camera.skipped,
                })
                .collect(),
            mean_render_ms,
        }
    }
}

impl Drop for CameraRig {
    fn drop(&mut self) {
        // Closing the job queue ends the render thread, which closes the consumer's queue.
        self.jobs.take();
        if let Some(thread) = self.render_thread.take() {
            let _ = thread.join();
        }
        if let Some(thread) = self.consumer_thread.take() {
            let _ = thread.join();
        }
    }
}

/// The model's id of each camera of `specs`; an error names a camera the scene lacks.
fn model_ids(sim: &Simulation, specs: &[CameraSpec]) -> Result<Vec<usize>> {
    specs
        .iter()
        .map(|spec| match sim.id(ObjectKind::Camera, &spec.name) {
            Some(id) => Ok(id),
            None => bail!(
                "the scene has no camera {:?} (--cameras; \"none\" renders nothing)",
                spec.name
            ),
        })
        .collect()
}

struct RenderThread {
    choice: RendererChoice,
    model: RenderModel,
    size: (u32, u32),
    sizes: Vec<(u32, u32)>,
    backgrounds: Option<Arc<Backgrounds>>,
    jobs: Receiver<RenderJob>,
    returns: mpsc::Sender<Views>,
    batches: SyncSender<FrameBatch>,
    totals: Arc<Mutex<RenderTotals>>,
    ready: mpsc::Sender<Result<String, String>>,
}

fn render_thread(work: RenderThread) {
    let gl = match GlContext::create(work.choice, work.size.0, work.size.1) {
        Ok(gl) => gl,
        Err(error) => {
            let _ = work.ready.send(Err(error.to_string()));
            return;
        }
    };
    let started = Instant::now();
    let mut context = RenderContext::new(&gl, &work.model);
    let description = format!("{} ({})", gl.description, gl.platform_name());
    tracing::debug!(
        seconds = started.elapsed().as_secs_f64(),
        "model uploaded to GL"
    );
    let (width, height) = context.size();
    if width < work.size.0 || height < work.size.1 {
        let _ = work.ready.send(Err(format!(
            "the GL offscreen buffer is {:?}, smaller than the {:?} asked for",
            context.size(),
            work.size
        )));
        return;
    }
    let _ = work.ready.send(Ok(description));
    let mut bottom_up = Vec::new();
    // Per camera: the picture shown and its pixels fitted to the frame, bottom-up.
    let mut fitted: Vec<Option<(usize, Vec<u8>)>> = vec![None; work.sizes.len()];
    for mut job in work.jobs.iter() {
        let started = Instant::now();
        let mut frames = Vec::with_capacity(job.due.len());
        for &camera in &job.due {
            let (width, height) = work.sizes[camera];
            bottom_up.resize(3 * width as usize * height as usize, 0);
            context.render(&mut job.views.0[camera], width, height, &mut bottom_up);
            if let (Some(backgrounds), Some(draw)) = (&work.backgrounds, job.background) {
                if let Some(index) = backgrounds.pick(camera, draw) {
                    let slot = &mut fitted[camera];
                    if slot.as_ref().map(|(shown, _)| *shown) != Some(index) {
                        let picture = backgrounds.picture(camera, index);
                        let pixels =
                            backgrounds::fitted_bottom_up(picture, width as usize, height as usize);
                        *slot = Some((index, pixels));
                    }
                    if let Some((_, pixels)) = slot {
                        backgrounds::composite(&mut bottom_up, pixels);
                    }
                }
            }
            frames.push(RenderedFrame {
                camera,
                rgb: flip_rows(&bottom_up, 3 * width as usize),
            });
        }
        let elapsed = started.elapsed();
        if let Ok(mut totals) = work.totals.lock() {
            for &camera in &job.due {
                totals.rendered[camera] += 1;
            }
            totals.frames += job.due.len() as u64;
            totals.seconds += elapsed.as_secs_f64();
        }
        let _ = work.returns.send(job.views);
        let batch = FrameBatch {
            sim_time: job.sim_time,
            frames,
            published: job.published,
        };
        if work.batches.send(batch).is_err() {
            break;
        }
    }
    // MuJoCo's GL resources go while their context is still current.
    drop(context);
    drop(gl);
}

/// GL reads rows bottom-up; images go top-down.
pub fn flip_rows(bottom_up: &[u8], row_bytes: usize) -> Vec<u8> {
    let mut top_down = Vec::with_capacity(bottom_up.len());
    for row in bottom_up.chunks_exact(row_bytes).rev() {
        top_down.extend_from_slice(row);
    }
    top_down
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flip_reverses_the_rows_only() {
        let bottom_up = [1, 2, 3, 4, 5, 6, 7, 8, 9];
        assert_eq!(flip_rows(&bottom_up, 3), [7, 8, 9, 4, 5, 6, 1, 2, 3]);
    }
}
