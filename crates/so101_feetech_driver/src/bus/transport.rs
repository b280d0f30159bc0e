//! The byte pipe under the servo bus: a serial port (USB adapter or the emulator's pty), behind a
//! trait so the bus logic does not care which.

use std::{
    io::{self, Read, Write},
    path::{Path, PathBuf},
    time::{Duration, Instant},
};

use serialport::{SerialPort, TTYPort};

/// A half-duplex byte stream with deadline-bounded reads.
pub trait Transport: Send {
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// Reads what is available, waiting at most until `deadline`; `Ok(0)` when nothing came.
    fn read_until(&mut self, buffer: &mut [u8], deadline: Instant) -> io::Result<usize>;
    /// A second handle on the same line, for last words from a panic hook or the signal thread
    /// (a broadcast torque off while the process dies); `None` where there is none.
    fn emergency_writer(&self) -> Option<Box<dyn Write + Send>> {
        None
    }
}

/// Where transports come from: opened at start and again after the link was lost.
pub trait Connector {
    type Transport: Transport;
    fn open(&mut self) -> io::Result<Self::Transport>;
    /// The port, in words (logs, /diagnostics).
    fn describe(&self) -> String;
}

/// A serial port by path.
#[derive(Debug, Clone)]
pub struct SerialConnector {
    pub path: PathBuf,
    pub baud: u32,
}

impl Connector for SerialConnector {
    type Transport = SerialTransport;

    fn open(&mut self) -> io::Result<SerialTransport> {
        SerialTransport::open(&self.path, self.baud).map_err(io::Error::from)
    }

    fn describe(&self) -> String {
        self.path.display().to_string()
    }
}

/// A serial port opened with the bus's settings (8N1, no flow control, raw).
pub struct SerialTransport {
    port: TTYPort,
    path: PathBuf,
}

impl SerialTransport {
    pub fn open(path: &Path, baud: u32) -> Result<Self, serialport::Error> {
        let name = path.to_string_lossy();
        let mut port = serialport::new(name.as_ref(), baud)
            .timeout(Duration::from_millis(10))
            .open_native()?;
        // Another process on the same bus would interleave packets; ptys do not support the lock.
        let _ = port.set_exclusive(true);
        port.clear(serialport::ClearBuffer::All)?;
        Ok(Self {
            port,
            path: path.to_owned(),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Transport for SerialTransport {
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        // No flush: on a tty it is tcdrain, which blocks until the other side took the bytes and
        // costs a round trip per request; the kernel sends them anyway.
        self.port.write_all(bytes)
    }

    fn read_until(&mut self, buffer: &mut [u8], deadline: Instant) -> io::Result<usize> {
        loop {
            let wait = deadline.saturating_duration_since(Instant::now());
            // Past the deadline this still looks once (drains what is already there).
            self.port
                .set_timeout(wait.max(Duration::from_micros(1)))
                .map_err(io::Error::from)?;
            return match self.port.read(buffer) {
                Ok(0) => Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "the serial port closed (adapter unplugged?)",
                )),
                Ok(count) => Ok(count),
                Err(error) if error.kind() == io::ErrorKind::TimedOut => Ok(0),
                // A signal (Ctrl-C asking for a clean shutdown) is not a broken port.
                Err(error) if error.kind() == io::ErrorKind::Interrupted => continue,
                Err(error) => Err(error),
            };
        }
    }

    fn emergency_writer(&self) -> Option<Box<dyn Write + Send>> {
        let port = self.port.try_clone_native().ok()?;
        Some(Box::new(port))
    }
}

/// USB-serial adapters with an FTDI-style latency timer (default 16 ms) hold replies back that
/// long, which caps the bus near 60 round trips a second. Returns the timer in ms where the kernel
/// exposes it for `port`.
pub fn usb_latency_timer_ms(port: &Path) -> Option<u32> {
    let real = std::fs::canonicalize(port).ok()?;
    let name = real.file_name()?.to_str()?;
    let text =
        std::fs::read_to_string(format!("/sys/class/tty/{name}/device/latency_timer")).ok()?;
    text.trim().parse().ok()
}
