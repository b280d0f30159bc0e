//! The control loop: commands in, physics forward one control period, frame out; paced by the
//! time mode.

use std::{
    sync::mpsc::sync_channel,
    time::{Duration, Instant},
};

use anyhow::{Context, Result};
use ros2_client::Publisher;
use so101_core::{
    contract::topics,
    ros::{
        arm_controller::ArmController, command_inbox::CommandInbox, parameters::ParameterServer,
        qos, shutdown::Shutdown, RosNode,
    },
};
use so101_msgs::std_msgs::String as StringMessage;

use so101_sim::{
    cameras::rig::{CameraRig, RigOptions},
    demo::{Script, PICK_AND_PLACE},
    env::{SimOptions, TaskEnv, TaskSettings},
    mujoco, scene,
};

use crate::{
    cameras::publish::{publish_batches, CameraTopics},
    cli::Args,
    pacing::{Pacer, TimeMode},
    parameters::{self, Setting},
    ros_io::{Frame, FramePublisher, NodeDiagnostics, PendingCall, SimServices},
};

/// Seconds of sim time between two /diagnostics messages.
const DIAGNOSTICS_PERIOD: f64 = 1.0;

/// How often --speed max looks for commands and service calls (wall time): at over 10 kHz of
/// control periods, polling every DDS reader each period costs more than the physics.
const MAX_SPEED_INTAKE_PERIOD: Duration = Duration::from_micros(500);

/// Longest single sleep of the loop, so shutdown and commands are noticed within it.
const MAX_SLEEP: Duration = Duration::from_millis(50);

/// How often lockstep mode looks for commands and /sim/step calls: briefly while a client is
/// stepping (each wait adds to every step's round trip), slowly once it has been idle a while.
const LOCKSTEP_POLL_BUSY: Duration = Duration::from_micros(20);
const LOCKSTEP_POLL_IDLE: Duration = Duration::from_millis(1);
const LOCKSTEP_BUSY_FOR: Duration = Duration::from_millis(200);

/// Loads the scene, starts the node and runs the loop until a signal or `--duration`.
pub fn run(args: Args) -> Result<()> {
    let mut simulation = scene::load(&args.scene, args.lite)?;
    if let Some(placements) = &args.camera_poses {
        placements.apply(&mut simulation)?;
        tracing::info!(file = %placements.source, cameras = ?placements.cameras.keys().collect::<Vec<_>>(), "cameras placed");
    }
    let settings = TaskSettings {
        kind: args.task,
        dense_reward: args.dense_reward,
    };
    let options = SimOptions::from_specs(&args.servo_params, &args.randomize);
    let env = TaskEnv::with_options(simulation, args.rate, settings, args.seed, options)
        .context("the scene does not fit the node")?;
    let time_mode = if args.lockstep {
        TimeMode::Lockstep
    } else {
        args.speed
    };
    tracing::info!(
        mujoco = %mujoco::version(),
        scene = %args.scene.display(),
        lite = args.lite,
        task = ?args.task,
        rate_hz = args.rate,
        timestep = env.world().timestep(),
        servos = %args.servo_params,
        randomize = %args.randomize,
        mode = ?time_mode,
        "simulation ready"
    );
    let shutdown = Shutdown::on_signals().context("cannot install the signal handlers")?;
    let mut node = RosNode::start("so101_sim_node", &args.node)?;
    let publisher = FramePublisher::start(&mut node)?;
    let inbox = CommandInbox::subscribe(&mut node)?;
    let arm = ArmController::serve(&mut node)?;
    let services = SimServices::serve(&mut node)?;
    let episode_settings = node.publisher(topics::SIM_EPISODE, qos::latched())?;
    let cameras = start_cameras(&args, time_mode, &env, &mut node)?;
    let parameters = ParameterServer::start(
        &mut node,
        parameters::declarations(&args, env.world().limits()),
    )?;
    let pacer = Pacer::new(
        match time_mode {
            TimeMode::Scaled { speed } => Some(speed),
            TimeMode::Max | TimeMode::Lockstep => None,
        },
        env.world().time(),
        Instant::now(),
    );
    let mut control = SimLoop {
        demo: args.demo.then(|| Script::new(&PICK_AND_PLACE)),
        demo_start: env.world().time(),
        next_diagnostics: env.world().time(),
        diagnostics: NodeDiagnostics::default(),
        args,
        time_mode,
        env,
        publisher,
        inbox,
        arm,
        services,
        episode_settings,
        parameters,
        pacer,
        cameras,
        _node: node,
    };
    control.run(&shutdown);
    Ok(())
}

/// The camera rig of `--cameras` (none for "none"), its frames published on the camera topics.
fn start_cameras(
    args: &Args,
    time_mode: TimeMode,
    env: &TaskEnv,
    node: &mut RosNode,
) -> Result<Option<CameraRig>> {
    let specs = args.camera_specs();
    if specs.is_empty() {
        return Ok(None);
    }
    let sim = env.world().simulation();
    let intrinsics = CameraRig::intrinsics(sim, &specs)?;
    let topics = specs
        .iter()
        .zip(intrinsics)
        .map(|(spec, intrinsics)| CameraTopics::advertise(node, &spec.name, intrinsics, args.jpeg))
        .collect::<Result<Vec<_>, _>>()?;
    let jpeg_quality = args.jpeg_quality;
    let options = RigOptions {
        renderer: args.renderer,
        show_collision_geoms: args.lite,
        shadows: args.camera_shadows,
        // Only real time may skip frames; every other mode renders each at its sim-time instant.
        wait_for_renderer: time_mode != TimeMode::Scaled { speed: 1.0 },
        backgrounds: env.backgrounds().map(ToOwned::to_owned),
    };
    let rig = CameraRig::start(sim, specs, options, env.world().time(), move |batches| {
        publish_batches(&topics, jpeg_quality, &batches)
    })
    .context("cannot start the cameras")?;
    tracing::info!(jpeg = args.jpeg, "camera topics advertised");
    Ok(Some(rig))
}

struct SimLoop {
    args: Args,
    time_mode: TimeMode,
    // Before `env`: the rig's render thread ends before the simulation it draws goes.
    cameras: Option<CameraRig>,
    env: TaskEnv,
    publisher: FramePublisher,
    inbox: CommandInbox,
    /// Trajectories (topic and FollowJointTrajectory action).
    arm: ArmController,
    services: SimServices,
    /// /sim/episode: what the current episode is simulated with.
    episode_settings: Publisher<StringMessage>,
    parameters: ParameterServer,
    pacer: Pacer,
    demo: Option<Script>,
    demo_start: f64,
    diagnostics: NodeDiagnostics,
    next_diagnostics: f64,
    // Declared last: dropped after the publishers and readers that belong to it.
    _node: RosNode,
}

impl SimLoop {
    fn run(&mut self, shutdown: &Shutdown) {
        // The state at time 0, so subscribers see the arm before the first step. The first frames
        // are waited for in every mode (the renderer's first draw is slow); then the clocks start.
        if self.cameras.is_some() {
            wait_until_published(self.capture_every_frame());
            self.pacer.restart(self.env.world().time(), Instant::now());
        }
        let deadline = self
            .args
            .duration
            .map(|seconds| Instant::now() + Duration::from_secs_f64(seconds.max(0.0)));
        let started = (
            Instant::now(),
            self.env.world().time(),
            self.env.world().total_steps(),
        );
        let mut last_intake = started.0 - MAX_SPEED_INTAKE_PERIOD;
        let mut last_lockstep_work = started.0;
        let commands_step = self.time_mode == TimeMode::Lockstep && self.args.step_on_command;
        self.publish(None);
        self.publish_episode_settings();
        while !shutdown.is_requested() && deadline.is_none_or(|deadline| Instant::now() < deadline)
        {
            let intake_due =
                self.time_mode != TimeMode::Max || last_intake.elapsed() >= MAX_SPEED_INTAKE_PERIOD;
            if intake_due {
                last_intake = Instant::now();
                self.apply_parameters();
                self.take_trajectories();
                if !commands_step {
                    self.apply_commands();
                }
                self.serve_resets();
            }
            if self.time_mode == TimeMode::Lockstep {
                let stepped = (commands_step && self.serve_command_steps()) | self.serve_steps();
                if stepped {
                    last_lockstep_work = Instant::now();
                } else {
                    self.publisher.flush();
                    std::thread::sleep(if last_lockstep_work.elapsed() < LOCKSTEP_BUSY_FOR {
                        LOCKSTEP_POLL_BUSY
                    } else {
                        LOCKSTEP_POLL_IDLE
                    });
                }
                continue;
            }
            if intake_due {
                self.refuse_steps();
            }
            if !self.wait_for_wall_clock() {
                continue;
            }
            let report = self.advance_period();
            self.capture_frames(false);
            self.publish(report);
        }
        self.publisher.flush();
        let wall_seconds = started.0.elapsed().as_secs_f64();
        let physics_steps = self.env.world().total_steps() - started.2;
        tracing::info!(
            sim_time = self.env.world().time(),
            sim_seconds_run = self.env.world().time() - started.1,
            wall_seconds,
            physics_steps,
            steps_per_second = physics_steps as f64 / wall_seconds,
            "shutting down"
        );
        if let Some(rig) = &self.cameras {
            let report = rig.diagnostics();
            for camera in &report.cameras {
                tracing::info!(
                    camera = %camera.name,
                    rendered = camera.rendered,
                    skipped = camera.skipped,
                    frames_per_second = camera.rendered as f64 / wall_seconds,
                    mean_render_ms = report.mean_render_ms,
                    "camera frames"
                );
            }
        }
    }

    /// Valid commands become the new targets (clamped) and preempt a trajectory; new
    /// trajectories start. The first of either ends the demo.
    fn apply_commands(&mut self) {
        let limits = *self.env.world().limits();
        let commands = self.inbox.drain();
        if !commands.is_empty() {
            self.arm.preempt("a direct command arrived");
        }
        if (!commands.is_empty() || self.arm.is_busy()) && self.demo.take().is_some() {
            tracing::info!("external command received: demo stopped");
        }
        for targets in commands {
            targets.apply_clamped(self.env.world_mut().targets_mut(), &limits);
        }
    }

    /// Trajectories and goals that arrived replace the running one.
    fn take_trajectories(&mut self) {
        let world = self.env.world();
        let limits = *world.limits();
        self.arm
            .take_new(world.time(), &|| world.arm_state().position, &limits, None);
    }

    /// Parameters set since the last look take effect now.
    fn apply_parameters(&mut self) {
        for change in self.parameters.changes() {
            match parameters::setting(&change.name, &change.value) {
                Some(Setting::DenseReward(dense)) => self.env.set_dense_reward(dense),
                Some(Setting::CameraRate(rate)) => {
                    if let Some(rig) = &mut self.cameras {
                        rig.set_rate(rate);
                    }
                }
                None => {}
            }
        }
    }

    fn publish_episode_settings(&self) {
        let settings = so101_sim::provenance::episode_settings(&self.env).to_string();
        if let Err(error) = self
            .episode_settings
            .publish(StringMessage { data: settings })
        {
            tracing::warn!("cannot publish /sim/episode: {error:?}");
        }
    }

    fn serve_resets(&mut self) {
        while let Some(call) = self.services.next_reset() {
            self.arm.preempt("the simulation was reset");
            let start = self.env.reset(None);
            self.publish_episode_settings();
            if let Some(rig) = &mut self.cameras {
                rig.restart(self.env.world().time());
            }
            self.diagnostics.episode += 1;
            self.demo_start = self.env.world().time();
            tracing::info!(
                episode = self.diagnostics.episode,
                x = start.x,
                y = start.y,
                yaw = start.yaw,
                "new episode"
            );
            let message = format!(
                "episode {} started: cube at x={:.4} y={:.4} yaw={:.4}",
                self.diagnostics.episode, start.x, start.y, start.yaw
            );
            // The caller sees the new episode on the topics, its camera frames too, by the time it
            // has the answer (in real time as well: a reset is a break in the episode anyway).
            let frames = self.capture_every_frame();
            self.publish_and_wait(None);
            wait_until_published(frames);
            self.pacer.restart(self.env.world().time(), Instant::now());
            self.services.answer_reset(call, true, message);
        }
    }

    /// Lockstep: one control period per /sim/step call, answered once its state is published.
    /// False when there was no call.
    fn serve_steps(&mut self) -> bool {
        let calls: Vec<PendingCall> = std::iter::from_fn(|| self.services.next_step()).collect();
        if calls.is_empty() {
            return false;
        }
        for call in calls {
            // A command or trajectory sent before this /sim/step call must act in this very step.
            self.take_trajectories();
            if !self.args.step_on_command {
                self.apply_commands();
            }
            self.step_and_publish();
            let time = self.env.world().time();
            self.services.answer_step(
                call,
                true,
                // The commands taken so far, so a client can tell that its command made it.
                format!("t={time:.6} commands={}", self.inbox.tally.accepted),
            );
        }
        true
    }

    /// Lockstep with --step-on-command: each valid command, in order, becomes the targets of one
    /// control period whose state is published before the next command is taken. False when no
    /// command came.
    fn serve_command_steps(&mut self) -> bool {
        let commands = self.inbox.drain();
        if commands.is_empty() {
            return false;
        }
        if self.demo.take().is_some() {
            tracing::info!("external command received: demo stopped");
        }
        self.arm.preempt("a direct command arrived");
        let limits = *self.env.world().limits();
        for targets in commands {
            targets.apply_clamped(self.env.world_mut().targets_mut(), &limits);
            self.step_and_publish();
        }
        true
    }

    /// One control period, its state (and camera frames) on the wire before this returns.
    fn step_and_publish(&mut self) {
        let report = self.advance_period();
        let frames = self.capture_frames(true);
        self.publish_and_wait(report);
        wait_until_published(frames);
    }

    fn refuse_steps(&mut self) {
        while let Some(call) = self.services.next_step() {
            let reason = "not in lockstep mode: start the node with --lockstep";
            self.services.answer_step(call, false, reason.into());
        }
    }

    /// Sleeps until the next period may run; false when it slept only part of the way (long waits
    /// are cut into slices so a signal or a command is not kept waiting).
    fn wait_for_wall_clock(&mut self) -> bool {
        let wait = self
            .pacer
            .wait_before(self.env.world().period_end(), Instant::now());
        if wait.is_zero() {
            return true;
        }
        // Nothing published may wait in a batch while the loop sleeps.
        self.publisher.flush();
        std::thread::sleep(wait.min(MAX_SLEEP));
        wait <= MAX_SLEEP
    }

    /// Runs the physics for one control period; returns the diagnostics when they are due.
    fn advance_period(&mut self) -> Option<NodeDiagnostics> {
        if let Some(script) = &self.demo {
            if self.env.world().time() - self.demo_start > script.duration() {
                self.env.world_mut().reset(None);
                self.demo_start = self.env.world().time();
            }
            *self.env.world_mut().targets_mut() =
                script.targets_at(self.env.world().time() - self.demo_start);
        }
        // The trajectory's setpoint for the end of this period.
        if let Some(targets) = self.arm.targets(self.env.world().period_end()) {
            let limits = *self.env.world().limits();
            targets.apply_clamped(self.env.world_mut().targets_mut(), &limits);
        }
        if !self.env.advance() {
            self.arm.preempt("the physics diverged");
            self.diagnostics.physics_divergences += 1;
            tracing::warn!(
                "the physics diverged (MuJoCo reset its state); the episode restarted from its start"
            );
        }
        if self.arm.is_busy() {
            let arm = self.env.world().arm_state();
            self.arm
                .after_period(self.env.world().time(), &arm.position, &arm.velocity);
        }
        if self.env.world().time() + 1e-9 < self.next_diagnostics {
            return None;
        }
        self.next_diagnostics = self.env.world().time() + DIAGNOSTICS_PERIOD;
        self.diagnostics.accepted_commands = self.inbox.tally.accepted;
        self.diagnostics.rejected_commands = self.inbox.tally.rejected;
        self.diagnostics.accepted_trajectories = self.arm.accepted;
        self.diagnostics.rejected_trajectories = self.arm.rejected;
        self.diagnostics.pacing_resyncs = self.pacer.resyncs;
        self.diagnostics.cameras = self.cameras.as_ref().map(CameraRig::diagnostics);
        Some(self.diagnostics.clone())
    }

    /// Hands the frames due now to the renderer. With `notify` (and a renderer that waits rather
    /// than skips), the answer fires once they are published.
    fn capture_frames(&mut self, notify: bool) -> Option<std::sync::mpsc::Receiver<()>> {
        let rig = self.cameras.as_mut()?;
        let time = self.env.world().time();
        let extras = self.env.view_extras();
        rig.capture(self.env.world_mut().simulation_mut(), time, extras, notify)
            .published()
    }

    /// Hands the frames due now (every camera's, after a start or reset) to the renderer, waiting
    /// for it in every mode; the answer fires once they are published.
    fn capture_every_frame(&mut self) -> Option<std::sync::mpsc::Receiver<()>> {
        let rig = self.cameras.as_mut()?;
        let time = self.env.world().time();
        let extras = self.env.view_extras();
        rig.capture_and_wait(self.env.world_mut().simulation_mut(), time, extras)
            .published()
    }

    fn publish(&mut self, diagnostics: Option<NodeDiagnostics>) {
        let frame = self.frame(diagnostics, None);
        self.publisher.send(frame);
    }

    fn publish_and_wait(&mut self, diagnostics: Option<NodeDiagnostics>) {
        let (done, published) = sync_channel(1);
        let frame = self.frame(diagnostics, Some(done));
        self.publisher.send(frame);
        let _ = published.recv();
    }

    fn frame(
        &self,
        diagnostics: Option<NodeDiagnostics>,
        published: Option<std::sync::mpsc::SyncSender<()>>,
    ) -> Frame {
        let observation = self.env.observe();
        Frame {
            sim_time: observation.time,
            arm: observation.arm,
            reward: observation.outcome.reward,
            success: observation.outcome.success,
            cube: observation.cube,
            diagnostics,
            published,
        }
    }
}

/// Waits for frames handed to the renderer to be on the wire (a lockstep step or a reset is
/// answered only then).
fn wait_until_published(frames: Option<std::sync::mpsc::Receiver<()>>) {
    if let Some(published) = frames {
        let _ = published.recv();
    }
}
