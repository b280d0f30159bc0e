//! Last words: when the process dies without its clean shutdown (a panic, a second Ctrl-C), a
//! broadcast Torque_Enable = 0 still goes out on a second handle of the bus, so no servo is left
//! stiff. A process killed with SIGKILL gets no last words: the servos keep their last goal (they
//! have no watchdog of their own).

use std::{
    io::Write,
    sync::{Mutex, MutexGuard, Once, PoisonError},
};

use crate::protocol::{encode_instruction, registers, Instruction, BROADCAST_ID};

/// The handle the last words go out on; `None` while no bus is open or the user asked to keep
/// torque on at exit.
static LINE: Mutex<Option<Box<dyn Write + Send>>> = Mutex::new(None);
static HOOK: Once = Once::new();

fn line() -> MutexGuard<'static, Option<Box<dyn Write + Send>>> {
    // A panic while the line was held must not silence the last words.
    LINE.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Where the last words go from now on (a new bus after a reconnect; `None` to stay silent).
pub fn set_line(writer: Option<Box<dyn Write + Send>>) {
    *line() = writer;
}

/// Broadcasts torque off twice on the line; whether the bytes were written.
pub fn torque_off_now() -> bool {
    let Ok(packet) = encode_instruction(
        BROADCAST_ID,
        &Instruction::Write {
            address: registers::TORQUE_ENABLE.address,
            data: vec![0],
        },
    ) else {
        return false;
    };
    let mut line = line();
    let Some(writer) = line.as_mut() else {
        return false;
    };
    let twice = [packet.as_slice(), packet.as_slice()].concat();
    writer
        .write_all(&twice)
        .and_then(|()| writer.flush())
        .is_ok()
}

/// Installs (once per process) a panic hook that says the last words, then does what the
/// previous hook did; with `end_process`, it then ends the process (exit code 101, as a panic on
/// the main thread does): a panic on any other thread must not leave the node running with the arm
/// limp while it believes torque is on.
pub fn install_panic_hook(end_process: bool) {
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if torque_off_now() {
                eprintln!("so101_feetech_driver: panic: torque off was broadcast to every servo");
            }
            previous(info);
            if end_process {
                std::process::exit(101);
            }
        }));
    });
}
