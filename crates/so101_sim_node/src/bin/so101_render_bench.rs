//! The anchor of the camera benchmark: a bare MuJoCo offscreen render loop on the node's scene, with
//! nothing else (no physics, no threads, no ROS): per frame one mjv_updateScene, one mjr_render and
//! one mjr_readPixels, cycling through the cameras. Prints one JSON line. With `--background`, each
//! frame is also keyed and composited over that picture, as the rig does for real backgrounds.
//!
//! Opens no DDS participant.

use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Parser;
use so101_core::ros::logging;
use so101_sim::{
    cameras::{
        backgrounds,
        spec::{self, FrameSize},
    },
    mujoco::{
        render::{RenderContext, SceneBuffer, VisualOptions},
        ObjectKind,
    },
    offscreen::{GlContext, RendererChoice},
    scene,
};

/// Milliseconds per frame of a bare MuJoCo offscreen render loop (the camera benchmark's anchor).
#[derive(Debug, Parser)]
#[command(version, about)]
struct Args {
    /// MJCF scene to load.
    #[arg(long, default_value = so101_core::robot::DEFAULT_SCENE)]
    scene: std::path::PathBuf,
    /// Mesh-free visual variant (as the node's --lite).
    #[arg(long)]
    lite: bool,
    /// Cameras to render in turn, comma-separated.
    #[arg(long, default_value = "top", value_delimiter = ',')]
    cameras: Vec<String>,
    /// Frame size.
    #[arg(long, default_value = "640x480", value_parser = spec::parse_size)]
    size: FrameSize,
    /// Frames measured (after the warm-up).
    #[arg(long, default_value_t = 300)]
    frames: u32,
    /// Frames drawn first and not measured (shader compilation, caches).
    #[arg(long, default_value_t = 10)]
    warmup: u32,
    /// Headless OpenGL platform.
    #[arg(long, value_enum, default_value = "auto")]
    renderer: RendererChoice,
    /// Render shadows.
    #[arg(long)]
    shadows: bool,
    /// A picture (JPEG) to composite behind the arm, cube and bin (real backgrounds).
    #[arg(long)]
    background: Option<std::path::PathBuf>,
}

fn main() -> Result<()> {
    logging::init();
    let args = Args::parse();
    let mut sim = scene::load(&args.scene, args.lite)?;
    let mut cameras = Vec::new();
    for name in &args.cameras {
        match sim.id(ObjectKind::Camera, name) {
            Some(id) => cameras.push(id),
            None => bail!("the scene has no camera {name:?}"),
        }
    }
    let FrameSize { width, height } = args.size;
    let gl = GlContext::create(args.renderer, width, height).context("no OpenGL context")?;
    let mut context = RenderContext::new(&gl, &sim.render_model(width, height));
    let options = VisualOptions::new(args.lite);
    let mut scene = SceneBuffer::new(&sim, args.shadows);
    let mut rgb = vec![0u8; 3 * width as usize * height as usize];
    let background = match &args.background {
        Some(path) => {
            let bytes = std::fs::read(path).with_context(|| format!("{}", path.display()))?;
            let picture = backgrounds::decode_jpeg(&bytes).map_err(anyhow::Error::msg)?;
            Some(backgrounds::fitted_bottom_up(
                &picture,
                width as usize,
                height as usize,
            ))
        }
        None => None,
    };
    let keyed = scene::background_geoms(&sim);
    let sky_radius = 0.5 * sim.view_distance();
    let mut frame = |index: u32| {
        let camera = cameras[index as usize % cameras.len()];
        sim.update_scene(&mut scene, camera, &options);
        if let Some(background) = &background {
            scene.key(&keyed, backgrounds::KEY, sky_radius);
            context.render(&mut scene, width, height, &mut rgb);
            backgrounds::composite(&mut rgb, background);
        } else {
            context.render(&mut scene, width, height, &mut rgb);
        }
    };
    for index in 0..args.warmup {
        frame(index);
    }
    let started = Instant::now();
    for index in 0..args.frames {
        frame(index);
    }
    let seconds = started.elapsed().as_secs_f64();
    println!(
        "{{\"renderer\": {:?}, \"platform\": {:?}, \"frames\": {}, \"ms_per_frame\": {:.4}, \"frames_per_second\": {:.2}}}",
        gl.description,
        gl.platform_name(),
        args.frames,
        1e3 * seconds / f64::from(args.frames),
        f64::from(args.frames) / seconds
    );
    drop(context);
    Ok(())
}
