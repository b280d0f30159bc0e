//! The control loop: commands in, physics forward one control period, frame out; paced by the
//! time mode.

use std::{
    sync::mpsc::sync_channel,
    time::{Duration, Instant},
};

use anyhow::{Context, Result};
use so101_core::ros::{shutdown::Shutdown, RosNode};

use crate::{
    cli::Args,
    demo::{Script, PICK_AND_PLACE},
    mujoco,
    pacing::{Pacer, TimeMode},
    placement::{CubePlacer, SpawnArea},
    ros_io::{CommandInbox, Frame, FramePublisher, NodeDiagnostics, SimServices},
    scene, task,
    world::World,
};

/// Where /sim/reset may put the cube (world frame, m): every point was picked into the bin by a
/// scripted grasp in this scene, and it stays at least 6.5 cm clear of the bin.
pub const CUBE_SPAWN_AREA: SpawnArea = SpawnArea {
    x: (0.15, 0.28),
    y: (-0.08, 0.12),
};

/// Seconds of sim time between two /diagnostics messages.
const DIAGNOSTICS_PERIOD: f64 = 1.0;

/// How often --speed max looks for commands and service calls (wall time).
const MAX_SPEED_INTAKE_PERIOD: Duration = Duration::from_micros(500);

/// How often lockstep mode looks for /sim/step calls while idle.
const LOCKSTEP_POLL: Duration = Duration::from_micros(100);

pub fn run(args: Args) -> Result<()> {
    let time_mode = if args.lockstep {
        TimeMode::Lockstep
    } else {
        args.speed
    };
    let simulation = scene::load(&args.scene, args.lite)?;
    let mut world =
        World::new(simulation, 1.0 / args.rate).context("the scene does not fit the node")?;
    tracing::info!(
        mujoco = %mujoco::version(),
        scene = %args.scene.display(),
        lite = args.lite,
        task = ?args.task,
        rate_hz = args.rate,
        timestep = world.timestep(),
        mode = ?time_mode,
        "simulation ready"
    );

    let shutdown = Shutdown::on_signals().context("cannot install the signal handlers")?;
    let mut node = RosNode::start("so101_sim_node", &args.node)?;
    let mut publisher = FramePublisher::start(&mut node)?;
    let mut inbox = CommandInbox::subscribe(&mut node)?;
    let services = SimServices::serve(&mut node)?;

    let mut placer = CubePlacer::new(CUBE_SPAWN_AREA, args.seed);
    let mut demo = args.demo.then(|| Script::new(&PICK_AND_PLACE));
    let mut demo_start = world.time();
    let mut diagnostics = NodeDiagnostics::default();
    let mut next_diagnostics = world.time();
    let mut pacer = Pacer::new(
        match time_mode {
            TimeMode::Scaled { speed } => Some(speed),
            TimeMode::Max | TimeMode::Lockstep => None,
        },
        world.time(),
        Instant::now(),
    );
    let deadline = args
        .duration
        .map(|seconds| Instant::now() + Duration::from_secs_f64(seconds.max(0.0)));

    let loop_start = Instant::now();
    let mut last_intake = loop_start - MAX_SPEED_INTAKE_PERIOD;
    let sim_time_at_start = world.time();
    let steps_at_start = world.total_steps();
    // The state at time 0, so subscribers see the arm before the first step.
    publisher.send(frame(&world, &args, None, None));
    while !shutdown.is_requested() && deadline.is_none_or(|deadline| Instant::now() < deadline) {
        // At --speed max the loop runs at over 10 kHz; polling every DDS reader on each period
        // costs a few syscalls each, so it polls at MAX_SPEED_INTAKE_PERIOD of wall time instead.
        let intake_due =
            time_mode != TimeMode::Max || last_intake.elapsed() >= MAX_SPEED_INTAKE_PERIOD;
        if intake_due {
            last_intake = Instant::now();
            let commands = inbox.drain();
            if !commands.is_empty() && demo.take().is_some() {
                tracing::info!("external command received: demo stopped");
            }
            let limits = *world.limits();
            for targets in commands {
                targets.apply_clamped(world.targets_mut(), &limits);
            }
            while let Some(call) = services.next_reset() {
                let start = placer.next_start();
                world.reset(Some(start));
                diagnostics.episode += 1;
                demo_start = world.time();
                tracing::info!(
                    episode = diagnostics.episode,
                    x = start.x,
                    y = start.y,
                    yaw = start.yaw,
                    "new episode"
                );
                let message = format!(
                    "episode {} started: cube at x={:.4} y={:.4} yaw={:.4}",
                    diagnostics.episode, start.x, start.y, start.yaw
                );
                services.answer_reset(call, true, message);
                publisher.send(frame(&world, &args, None, None));
            }
        }
        let steps_requested = match time_mode {
            TimeMode::Lockstep => {
                let mut calls = Vec::new();
                while let Some(call) = services.next_step() {
                    calls.push(call);
                }
                calls
            }
            _ if !intake_due => Vec::new(),
            _ => {
                while let Some(call) = services.next_step() {
                    services.answer_step(
                        call,
                        false,
                        "not in lockstep mode: start the node with --lockstep".into(),
                    );
                }
                Vec::new()
            }
        };
        if time_mode == TimeMode::Lockstep && steps_requested.is_empty() {
            publisher.flush();
            std::thread::sleep(LOCKSTEP_POLL);
            continue;
        }

        let periods = steps_requested.len().max(1);
        let mut calls = steps_requested.into_iter();
        for _ in 0..periods {
            let wait = pacer.wait_before(world.time() + 1.0 / args.rate, Instant::now());
            if !wait.is_zero() {
                // Nothing published may wait in a batch while the loop sleeps.
                publisher.flush();
                std::thread::sleep(wait);
            }
            if let Some(script) = &demo {
                let elapsed = world.time() - demo_start;
                if elapsed > script.duration() {
                    world.reset(None);
                    demo_start = world.time();
                }
                *world.targets_mut() = script.targets_at(world.time() - demo_start);
            }
            if !world.advance() {
                diagnostics.mujoco_warnings += 1;
                tracing::warn!("MuJoCo reported a numerical problem and reset the state");
            }
            let report = (world.time() + 1e-9 >= next_diagnostics).then(|| {
                next_diagnostics = world.time() + DIAGNOSTICS_PERIOD;
                diagnostics.accepted_commands = inbox.accepted;
                diagnostics.rejected_commands = inbox.rejected;
                diagnostics.pacing_resyncs = pacer.resyncs;
                diagnostics.clone()
            });
            match calls.next() {
                Some(call) => {
                    // Answer /sim/step only once the new state is published.
                    let (done, published) = sync_channel(1);
                    publisher.send(frame(&world, &args, report, Some(done)));
                    let _ = published.recv();
                    services.answer_step(call, true, format!("t={:.6}", world.time()));
                }
                None => publisher.send(frame(&world, &args, report, None)),
            }
        }
    }
    let wall_seconds = loop_start.elapsed().as_secs_f64();
    let physics_steps = world.total_steps() - steps_at_start;
    tracing::info!(
        sim_time = world.time(),
        sim_seconds_run = world.time() - sim_time_at_start,
        wall_seconds,
        physics_steps,
        steps_per_second = physics_steps as f64 / wall_seconds,
        "shutting down"
    );
    drop(publisher);
    Ok(())
}

fn frame(
    world: &World,
    args: &Args,
    diagnostics: Option<NodeDiagnostics>,
    published: Option<std::sync::mpsc::SyncSender<()>>,
) -> Frame {
    let outcome = task::evaluate(args.task, args.dense_reward, &world.task_observation());
    Frame {
        sim_time: world.time(),
        arm: world.arm_state(),
        reward: outcome.reward,
        success: outcome.success,
        cube: world.cube_pose(),
        diagnostics,
        published,
    }
}
