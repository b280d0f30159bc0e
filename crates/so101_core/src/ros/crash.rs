//! A last word from a node that dies of a fatal signal (SIGSEGV, SIGBUS, SIGILL, SIGFPE): the
//! signal, the faulting address, the thread and the stack (return addresses with the library each
//! lies in, symbolised where the library exports symbols) on stderr, then the signal's default
//! action as before, so the exit status still tells the signal. A crash inside a C library (MuJoCo,
//! Mesa, the GL driver) otherwise leaves only "SIGSEGV" to go on.
//!
//! The handler runs in a broken process, so it only does what is safe there: it formats into a
//! buffer on its own stack, writes with write(2) and walks the stack with glibc's backtrace
//! (primed at install time: its first call loads libgcc_s). Rust's own handler, which reports a
//! thread's stack overflow, runs after it.
#![allow(unsafe_code)]

use std::{ffi::c_int, sync::OnceLock};

const SIGNALS: [c_int; 4] = [libc::SIGSEGV, libc::SIGBUS, libc::SIGILL, libc::SIGFPE];
const MAX_FRAMES: usize = 64;

/// The handlers installed before this one (Rust's stack-overflow report for SIGSEGV and SIGBUS).
static PREVIOUS: OnceLock<[libc::sigaction; 4]> = OnceLock::new();

/// Installs the report for the process (once; later calls do nothing).
pub fn install() {
    PREVIOUS.get_or_init(|| {
        let mut frames = [std::ptr::null_mut(); 4];
        // SAFETY: `frames` has room for the 4 entries asked for; the call loads libgcc_s now, not
        // in the handler.
        unsafe { libc::backtrace(frames.as_mut_ptr(), frames.len() as c_int) };
        // SAFETY: a zeroed sigaction is a valid value (no handler, empty mask).
        let mut previous: [libc::sigaction; 4] = unsafe { std::mem::zeroed() };
        for (index, &signal) in SIGNALS.iter().enumerate() {
            // SAFETY: a zeroed sigaction is valid; the handler has the SA_SIGINFO signature and runs
            // on the thread's alternate stack where there is one (Rust's threads have one).
            unsafe {
                let mut action: libc::sigaction = std::mem::zeroed();
                action.sa_sigaction = on_fatal_signal as *const () as usize;
                action.sa_flags = libc::SA_SIGINFO | libc::SA_ONSTACK;
                libc::sigemptyset(&mut action.sa_mask);
                libc::sigaction(signal, &action, &mut previous[index]);
            }
        }
        previous
    });
}

extern "C" fn on_fatal_signal(
    signal: c_int,
    info: *mut libc::siginfo_t,
    context: *mut libc::c_void,
) {
    let mut line = Line::default();
    line.push(b"\nfatal signal ");
    line.push(signal_name(signal));
    line.push(b" at address 0x");
    // SAFETY: the kernel passes a valid siginfo to an SA_SIGINFO handler.
    line.push_hex(unsafe { (*info).si_addr() } as usize);
    line.push(b" in thread '");
    let mut name = [0u8; 32];
    // SAFETY: `name` is writable for its length; for the calling thread this is a prctl.
    if unsafe {
        libc::pthread_getname_np(libc::pthread_self(), name.as_mut_ptr().cast(), name.len())
    } == 0
    {
        let end = name.iter().position(|&b| b == 0).unwrap_or(name.len());
        line.push(&name[..end]);
    }
    line.push(b"'; its stack:\n");
    line.write();
    let mut frames = [std::ptr::null_mut(); MAX_FRAMES];
    // SAFETY: `frames` has room for MAX_FRAMES entries; backtrace_symbols_fd writes to fd 2
    // without allocating.
    unsafe {
        let count = libc::backtrace(frames.as_mut_ptr(), MAX_FRAMES as c_int);
        libc::backtrace_symbols_fd(frames.as_ptr(), count, libc::STDERR_FILENO);
    }
    // The handler the signal had before (the default while install() is still under way).
    let previous = SIGNALS
        .iter()
        .position(|&s| s == signal)
        .and_then(|index| Some(PREVIOUS.get()?[index]));
    let handler = previous.map_or(libc::SIG_DFL, |previous| previous.sa_sigaction);
    if handler == libc::SIG_DFL || handler == libc::SIG_IGN {
        // SAFETY: restoring the default action; returning re-runs the faulting instruction, which
        // then ends the process with the signal (a raise() for the signals that were sent).
        unsafe {
            libc::signal(signal, libc::SIG_DFL);
            if (*info).si_code <= 0 {
                libc::raise(signal);
            }
        }
    } else if previous.is_some_and(|previous| previous.sa_flags & libc::SA_SIGINFO != 0) {
        // SAFETY: the previous handler was installed with SA_SIGINFO and so takes these arguments.
        let previous: extern "C" fn(c_int, *mut libc::siginfo_t, *mut libc::c_void) =
            unsafe { std::mem::transmute(handler) };
        previous(signal, info, context);
    } else {
        // SAFETY: a plain handler takes the signal number only.
        let previous: extern "C" fn(c_int) = unsafe { std::mem::transmute(handler) };
        previous(signal);
    }
}

fn signal_name(signal: c_int) -> &'static [u8] {
    match signal {
        libc::SIGSEGV => b"SIGSEGV",
        libc::SIGBUS => b"SIGBUS",
        libc::SIGILL => b"SIGILL",
        libc::SIGFPE => b"SIGFPE",
        _ => b"(unknown)",
    }
}

/// A line built without allocating.
struct Line {
    bytes: [u8; 256],
    len: usize,
}

impl Default for Line {
    fn default() -> Self {
        Self {
            bytes: [0; 256],
            len: 0,
        }
    }
}

impl Line {
    fn push(&mut self, text: &[u8]) {
        let room = self.bytes.len() - self.len;
        let take = text.len().min(room);
        self.bytes[self.len..self.len + take].copy_from_slice(&text[..take]);
        self.len += take;
    }

    fn push_hex(&mut self, value: usize) {
        let mut digits = [0u8; 16];
        let mut count = 0;
        let mut rest = value;
        loop {
            digits[count] = b"0123456789abcdef"[rest & 0xf];
            count += 1;
            rest >>= 4;
            if rest == 0 {
                break;
            }
        }
        digits[..count].reverse();
        self.push(&digits[..count]);
    }

    fn write(&self) {
        // SAFETY: writes `len` initialised bytes of the buffer to stderr.
        unsafe { libc::write(libc::STDERR_FILENO, self.bytes.as_ptr().cast(), self.len) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_digits_are_the_value_s() {
        let mut line = Line::default();
        line.push_hex(0x7f3a_0000_1c20);
        line.push(b" ");
        line.push_hex(0);
        assert_eq!(&line.bytes[..line.len], b"7f3a00001c20 0");
    }

    /// Set in the child process of `a_crash_is_reported_and_still_ends_the_process`.
    const CHILD: &str = "SO101_CRASH_TEST_CHILD";

    #[test]
    fn crashing_child() {
        if std::env::var_os(CHILD).is_none() {
            return; // only ever does something as the child below
        }
        install();
        // SAFETY: not safe at all: the crash under test.
        unsafe { std::ptr::null_mut::<u64>().write_volatile(1) };
    }

    #[test]
    fn a_crash_is_reported_and_still_ends_the_process() {
        use std::os::unix::process::ExitStatusExt;

        let output = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "ros::crash::tests::crashing_child",
                "--test-threads=1",
            ])
            .env(CHILD, "1")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.signal(), Some(libc::SIGSEGV), "{stderr}");
        assert!(
            stderr.contains("fatal signal SIGSEGV at address 0x0 in thread 'ros::crash::tes"),
            "{stderr}"
        );
        // The stack: return addresses with the binary they lie in.
        let test_binary = std::env::current_exe().unwrap();
        let name = test_binary.file_name().unwrap().to_string_lossy();
        assert!(stderr.matches(name.as_ref()).count() >= 2, "{stderr}");
    }

    #[test]
    fn a_long_line_is_cut_not_overrun() {
        let mut line = Line::default();
        for _ in 0..100 {
            line.push(b"abcdef");
        }
        assert_eq!(line.len, 256);
    }
}
