//! Serving the emulated bus on a pseudo-terminal: the driver opens the slave side (or a symlink to
//! it) as if it were the USB-serial adapter.

use std::{
    fs::File,
    io::{Read, Write},
    os::fd::{AsFd, OwnedFd},
    path::{Path, PathBuf},
    sync::{
        atomic::{AtomicBool, Ordering},
        Arc, Condvar, Mutex, MutexGuard, PoisonError,
    },
    thread::JoinHandle,
    time::{Duration, Instant},
};

use nix::{
    fcntl::{fcntl, FcntlArg, OFlag},
    poll::{poll, PollFd, PollFlags},
    pty::{openpty, OpenptyResult, Winsize},
    sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg, Termios},
};
use serde::Serialize;
use so101_core::{
    robot::JOINT_COUNT,
    servo::{ArmServoParams, ARM_LOADS},
};

use so101_feetech_driver::{
    calibration::ArmCalibration,
    protocol::{registers as reg, PacketReader},
};

use crate::{
    bus::{calibrated_servos, BusEmulator, SlotSnapshot, SlotState, Timing},
    control::ControlCommand,
    error::EmulatorError,
    servo::{ServoModel, DEFAULT_TAU},
};

/// How long one poll of the master waits, so stop and hangup requests are seen promptly.
const POLL_MS: u8 = 2;
/// Replies are due to the microsecond: sleep until this long before, then spin.
const SPIN_BEFORE: Duration = Duration::from_micros(150);
/// How long `hangup` waits for the serving thread to close the pty.
const HANGUP_ACK_TIMEOUT: Duration = Duration::from_secs(1);
/// Between attempts to reopen a pty after a failure.
const REOPEN_RETRY: Duration = Duration::from_millis(200);

#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// One slot per id, in bus order (factory servos). Ignored with `calibration`.
    pub ids: Vec<u8>,
    /// An arm calibrated and configured by LeRobot instead of factory servos: the six servos of
    /// the calibration, in joint order (a state file that exists wins over it).
    pub calibration: Option<ArmCalibration>,
    /// Which slots are plugged at start (by index; missing entries are unplugged). `None`: all.
    pub plugged: Option<Vec<bool>>,
    pub timing: Timing,
    /// Time constant of each shaft's approach to its goal.
    pub tau: Duration,
    /// Where the servos' flash and shaft positions persist across runs.
    pub state_file: Option<PathBuf>,
    /// A symlink to the slave, kept pointing at the current pty across hangups.
    pub link: Option<PathBuf>,
    /// Seed of the fault injection's random numbers.
    pub seed: u64,
    /// Overrides every servo's initial Return_Delay_Time (units of 2 us).
    pub return_delay: Option<u8>,
    /// The shafts move as the STS3215 model with these parameters (slot i drives joint i of the
    /// arm, its mechanics and load; the dead zones become the servos' CW/CCW_Dead_Zone) instead
    /// of the first-order approach of `tau`.
    pub servo_params: Option<ArmServoParams>,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        Self {
            ids: (1..=6).collect(),
            calibration: None,
            plugged: None,
            timing: Timing::Instant,
            tau: DEFAULT_TAU,
            state_file: None,
            link: None,
            seed: 0,
            return_delay: None,
            servo_params: None,
        }
    }
}

/// A running emulator: a thread serving the bus on a pty. Dropping it stops the thread, saves the
/// state file and removes the link.
pub struct Emulator {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

struct Shared {
    bus: Mutex<BusEmulator>,
    /// Zero of the bus's clock.
    epoch: Instant,
    link: Option<PathBuf>,
    state_file: Option<PathBuf>,
    slave_path: Mutex<PathBuf>,
    stop: AtomicBool,
    hangup: Mutex<HangupState>,
    hangup_done: Condvar,
}

#[derive(Default)]
struct HangupState {
    /// A hangup the serving thread has yet to perform, with its downtime.
    requested: Option<Duration>,
    /// Hangups performed so far (the pty was closed).
    performed: u64,
}

/// The open pty: the master that the emulator serves, and a slave fd kept open so the master
/// never sees EIO while no client has the port open.
struct Pty {
    master: File,
    _slave: OwnedFd,
    slave_path: PathBuf,
}

#[derive(Serialize)]
struct Dump<'a> {
    slots: &'a [SlotSnapshot],
}

fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic elsewhere must not take the bus down with it; the state is still consistent.
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Emulator {
    pub fn start(config: EmulatorConfig) -> Result<Self, EmulatorError> {
        let bus = build_bus(&config)?;
        if let Some(link) = &config.link {
            check_link_path(link)?;
        }
        let pty = open_pty()?;
        if let Some(link) = &config.link {
            point_link(link, &pty.slave_path)?;
        }
        let shared = Arc::new(Shared {
            bus: Mutex::new(bus),
            epoch: Instant::now(),
            link: config.link.clone(),
            state_file: config.state_file.clone(),
            slave_path: Mutex::new(pty.slave_path.clone()),
            stop: AtomicBool::new(false),
            hangup: Mutex::new(HangupState::default()),
            hangup_done: Condvar::new(),
        });
        tracing::info!(
            slave = %pty.slave_path.display(),
            link = ?config.link,
            timing = ?config.timing,
            ids = ?config.ids,
            "servo emulator started"
        );
        let serving = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("servo-emulator".into())
            .spawn(move || serve(&serving, Some(pty)))
            .map_err(EmulatorError::Thread)?;
        Ok(Self {
            shared,
            thread: Some(thread),
        })
    }

    /// What clients open: the link if one was asked for, else the current slave path.
    pub fn port_path(&self) -> PathBuf {
        match &self.shared.link {
            Some(link) => link.clone(),
            None => lock(&self.shared.slave_path).clone(),
        }
    }

    /// Every slot as `dump` shows it, physics brought up to now.
    pub fn snapshot(&self) -> Vec<SlotSnapshot> {
        let mut bus = lock(&self.shared.bus);
        bus.advance_to(self.shared.epoch.elapsed());
        bus.snapshot()
    }

    /// Applies a control command; the answer is `ok`, or the JSON line for `dump`. `quit` is
    /// answered `ok` and left to the caller.
    pub fn control(&self, command: ControlCommand) -> Result<String, String> {
        match command {
            ControlCommand::Dump => serde_json::to_string(&Dump {
                slots: &self.snapshot(),
            })
            .map_err(|error| error.to_string()),
            ControlCommand::Hangup(downtime) => self.hangup(downtime).map(|()| "ok".into()),
            ControlCommand::Quit => Ok("ok".into()),
            command => {
                let mut bus = lock(&self.shared.bus);
                bus.advance_to(self.shared.epoch.elapsed());
                command.apply(&mut bus).map_err(|error| error.to_string())?;
                Ok("ok".into())
            }
        }
    }

    /// Parses and applies one control line.
    pub fn control_line(&self, line: &str) -> Result<String, String> {
        let command: ControlCommand = line.parse().map_err(|error| format!("{error}"))?;
        self.control(command)
    }

    /// Unplugs the adapter: returns once the pty is closed; it comes back after `downtime`.
    fn hangup(&self, downtime: Duration) -> Result<(), String> {
        let mut state = lock(&self.shared.hangup);
        let before = state.performed;
        state.requested = Some(downtime);
        let (state, _) = self
            .shared
            .hangup_done
            .wait_timeout_while(state, HANGUP_ACK_TIMEOUT, |state| state.performed == before)
            .unwrap_or_else(PoisonError::into_inner);
        if state.performed == before {
            return Err("the serving thread did not hang up in time".into());
        }
        Ok(())
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
        if let Some(link) = &self.shared.link {
            remove_link(link);
        }
        // The shafts' positions persist too, so the arm is where it was left at the next start.
        self.shared.save_state();
    }
}

impl Shared {
    fn save_state(&self) {
        if let Some(path) = &self.state_file {
            if let Err(error) = lock(&self.bus).save_state(path) {
                tracing::warn!(%error, "servo state not saved");
            }
        }
    }

    fn take_hangup(&self) -> Option<Duration> {
        lock(&self.hangup).requested.take()
    }

    fn hangup_performed(&self) {
        lock(&self.hangup).performed += 1;
        self.hangup_done.notify_all();
    }

    /// Keeps the adapter unplugged for `downtime` (a further hangup meanwhile restarts the
    /// count); false if stop was requested meanwhile.
    fn stay_unplugged(&self, downtime: Duration) -> bool {
        let mut end = Instant::now() + downtime;
        while !self.stop.load(Ordering::SeqCst) {
            if let Some(more) = self.take_hangup() {
                end = Instant::now() + more;
                self.hangup_performed();
            }
            let left = end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return true;
            }
            std::thread::sleep(left.min(Duration::from_millis(u64::from(POLL_MS))));
        }
        false
    }

    fn reopen(&self) -> Option<Pty> {
        let pty = open_pty().and_then(|pty| {
            if let Some(link) = &self.link {
                point_link(link, &pty.slave_path)?;
            }
            Ok(pty)
        });
        match pty {
            Ok(pty) => {
                *lock(&self.slave_path) = pty.slave_path.clone();
                tracing::info!(slave = %pty.slave_path.display(), "adapter plugged back in");
                Some(pty)
            }
            Err(error) => {
                tracing::warn!(%error, "cannot reopen the pty; retrying");
                None
            }
        }
    }
}

fn build_bus(config: &EmulatorConfig) -> Result<BusEmulator, EmulatorError> {
    let servos = match &config.calibration {
        Some(calibration) => calibrated_servos(calibration),
        None => config
            .ids
            .iter()
            .copied()
            .map(ServoModel::factory)
            .collect(),
    };
    let slots = servos
        .into_iter()
        .enumerate()
        .map(|(index, mut servo)| {
            servo.set_tau(config.tau);
            if let Some(params) = &config.servo_params {
                let joint = index % JOINT_COUNT;
                let servo_params = params.0[joint];
                for (register, value) in [
                    (reg::CW_DEAD_ZONE, servo_params.registers.cw_dead_zone),
                    (reg::CCW_DEAD_ZONE, servo_params.registers.ccw_dead_zone),
                ] {
                    // Checked when the file was read: a small whole number of ticks.
                    let _ = servo.set_factory_register(register, value.round() as i32);
                }
                servo.set_dynamics(servo_params.mechanics, ARM_LOADS[joint]);
            }
            let plugged = match &config.plugged {
                Some(plugged) => plugged.get(index).copied().unwrap_or(false),
                None => true,
            };
            SlotState {
                servo,
                plugged,
                silent: false,
            }
        })
        .collect();
    let mut bus = BusEmulator::new(slots, config.timing, config.seed);
    if let Some(path) = &config.state_file {
        if bus.load_state(path)? {
            tracing::info!(path = %path.display(), "servo state restored");
        }
    }
    if let Some(delay) = config.return_delay {
        for slot in &mut bus.slots {
            // An operator's override of the live register, not a write: the flash keeps its value.
            let _ = slot
                .servo
                .set_register(reg::RETURN_DELAY_TIME, i32::from(delay));
        }
    }
    Ok(bus)
}

fn open_pty() -> Result<Pty, EmulatorError> {
    let OpenptyResult { master, slave } =
        openpty(None::<&Winsize>, None::<&Termios>).map_err(EmulatorError::OpenPty)?;
    // Raw and without echo before any client opens it: an echo would look like a reply.
    let mut termios = tcgetattr(&slave).map_err(EmulatorError::RawMode)?;
    cfmakeraw(&mut termios);
    tcsetattr(&slave, SetArg::TCSANOW, &termios).map_err(EmulatorError::RawMode)?;
    // Non-blocking: a client that stops reading must not stall the emulator once the buffer fills.
    fcntl(&master, FcntlArg::F_SETFL(OFlag::O_NONBLOCK)).map_err(EmulatorError::OpenPty)?;
    let slave_path = nix::unistd::ttyname(&slave).map_err(EmulatorError::OpenPty)?;
    Ok(Pty {
        master: File::from(master),
        _slave: slave,
        slave_path,
    })
}

fn check_link_path(link: &Path) -> Result<(), EmulatorError> {
    let bad = |reason: &str| EmulatorError::BadLink {
        path: link.to_owned(),
        reason: reason.to_owned(),
    };
    if link.file_name().is_none() {
        return Err(bad("it names no file"));
    }
    let parent = link
        .parent()
        .filter(|parent| !parent.as_os_str().is_empty());
    if parent.is_some_and(|parent| !parent.is_dir()) {
        return Err(bad("its directory does not exist"));
    }
    match std::fs::symlink_metadata(link) {
        Ok(metadata) if !metadata.file_type().is_symlink() => {
            Err(bad("something other than a symlink is there"))
        }
        _ => Ok(()),
    }
}

/// Points `link` at `target`, replacing an old link atomically (a new link, then a rename), so a
/// client never finds the path missing while it is updated.
fn point_link(link: &Path, target: &Path) -> Result<(), EmulatorError> {
    let mut temporary = link.as_os_str().to_owned();
    temporary.push(format!(".tmp{}", std::process::id()));
    let temporary = PathBuf::from(temporary);
    let _ = std::fs::remove_file(&temporary);
    std::os::unix::fs::symlink(target, &temporary)
        .and_then(|()| std::fs::rename(&temporary, link))
        .map_err(|error| EmulatorError::BadLink {
            path: link.to_owned(),
            reason: error.to_string(),
        })
}

fn remove_link(link: &Path) {
    let is_symlink = std::fs::symlink_metadata(link)
        .map(|metadata| metadata.file_type().is_symlink())
        .unwrap_or(false);
    if is_symlink {
        if let Err(error) = std::fs::remove_file(link) {
            tracing::warn!(link = %link.display(), %error, "cannot remove the link");
        }
    }
}

/// The serving thread: requests in, replies out at their due time, hangups on demand.
fn serve(shared: &Shared, mut pty: Option<Pty>) {
    let mut reader = PacketReader::new();
    let mut buffer = [0u8; 1024];
    while !shared.stop.load(Ordering::SeqCst) {
        if let Some(downtime) = shared.take_hangup() {
            pty = None;
            if let Some(link) = &shared.link {
                remove_link(link);
            }
            reader = PacketReader::new();
            tracing::info!(?downtime, "adapter unplugged (pty closed)");
            shared.hangup_performed();
            if shared.stay_unplugged(downtime) {
                pty = shared.reopen();
            }
            continue;
        }
        let Some(open) = pty.as_mut() else {
            if shared.stay_unplugged(REOPEN_RETRY) {
                pty = shared.reopen();
            }
            continue;
        };
        if !readable(&open.master) {
            continue;
        }
        match open.master.read(&mut buffer) {
            Ok(count) => reader.push(&buffer[..count]),
            Err(error) if error.kind() == std::io::ErrorKind::WouldBlock => continue,
            Err(error) => {
                tracing::debug!(%error, "pty read failed");
                std::thread::sleep(Duration::from_millis(u64::from(POLL_MS)));
                continue;
            }
        }
        // Frames failing their checksum are skipped: real servos ignore them.
        while let Some(frame) = reader.next_frame() {
            if let Ok(packet) = frame {
                serve_packet(shared, &mut open.master, &packet);
            }
        }
    }
}

fn readable(master: &File) -> bool {
    let mut fds = [PollFd::new(master.as_fd(), PollFlags::POLLIN)];
    matches!(poll(&mut fds, POLL_MS), Ok(ready) if ready > 0)
}

fn serve_packet(shared: &Shared, master: &mut File, packet: &[u8]) {
    let arrived = shared.epoch.elapsed();
    let (response, save) = {
        let mut bus = lock(&shared.bus);
        let response = bus.handle(arrived, packet);
        (response, bus.take_save_needed())
    };
    tracing::debug!(
        request = ?packet,
        reply = ?response.bytes,
        due_us = response.due.saturating_sub(arrived).as_micros() as u64,
        "packet"
    );
    if !response.bytes.is_empty() {
        wait_until(shared.epoch + response.due, &shared.stop);
        if let Err(error) = master.write_all(&response.bytes) {
            tracing::debug!(%error, "reply not delivered (client not reading?)");
        }
    }
    if save {
        shared.save_state();
    }
}

/// Sleeps until shortly before `deadline`, then spins: a plain sleep overshoots by tens of us.
/// Returns early when stop is requested (an injected delay may be long).
fn wait_until(deadline: Instant, stop: &AtomicBool) {
    let longest_sleep = Duration::from_millis(u64::from(POLL_MS));
    while !stop.load(Ordering::Relaxed) {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return;
        }
        if left > SPIN_BEFORE {
            std::thread::sleep((left - SPIN_BEFORE).min(longest_sleep));
        } else {
            std::hint::spin_loop();
        }
    }
}
