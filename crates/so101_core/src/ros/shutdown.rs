//! Clean shutdown on SIGINT/SIGTERM: the first signal asks every loop to stop so publishers are
//! dropped and the DDS participant says goodbye to its peers; a second signal exits at once.
//!
//! Also on SIGCONT, the resumption after a stop (Ctrl+Z then `fg`): the stop interrupts the DDS
//! library's waits, and RustDDS 0.15.1 ends its event loop and discovery threads on that error
//! (EINTR), so the resumed process could no longer hear or reach a peer. It says so and stops
//! cleanly instead of running on deaf and mute; start it again.

use std::sync::{
    atomic::{AtomicBool, Ordering},
    Arc,
};

use signal_hook::{
    consts::{SIGCONT, SIGINT, SIGTERM},
    iterator::Signals,
};

/// A cloneable handle on "has shutdown been requested?".
#[derive(Clone)]
pub struct Shutdown {
    requested: Arc<AtomicBool>,
    /// Closed (its sender dropped) when shutdown is requested: every waiter wakes at once.
    closed: smol::channel::Receiver<()>,
    trigger: Arc<std::sync::Mutex<Option<smol::channel::Sender<()>>>>,
}

impl Shutdown {
    /// A handle that only [`Shutdown::request`] triggers (tests, `--duration`).
    pub fn new() -> Self {
        let (sender, receiver) = smol::channel::bounded(1);
        Self {
            requested: Arc::new(AtomicBool::new(false)),
            closed: receiver,
            trigger: Arc::new(std::sync::Mutex::new(Some(sender))),
        }
    }

    /// A handle triggered by SIGINT or SIGTERM. A second signal exits the process with status 130.
    pub fn on_signals() -> std::io::Result<Self> {
        Self::on_signals_then(|| {})
    }

    /// Like [`Shutdown::on_signals`], with `last_words` said before a second signal ends the
    /// process (a device left in a safe state when the clean shutdown is cut short).
    pub fn on_signals_then(last_words: impl FnOnce() + Send + 'static) -> std::io::Result<Self> {
        let shutdown = Self::new();
        let mut signals = Signals::new([SIGINT, SIGTERM, SIGCONT])?;
        let handle = shutdown.clone();
        std::thread::Builder::new()
            .name("signals".into())
            .spawn(move || {
                let mut requested = false;
                for signal in signals.forever() {
                    if signal == SIGCONT {
                        // `timeout` and a shell's kill send SIGCONT after their SIGTERM: only a
                        // resumption before any request counts.
                        if !requested {
                            tracing::error!(
                                "resumed after a stop (Ctrl+Z, a debugger): the DDS library's \
                                 threads end when a stop interrupts them, so this node can no \
                                 longer reach its peers; stopping: start it again"
                            );
                            requested = true;
                            handle.request();
                        }
                    } else if !requested {
                        tracing::info!(signal, "shutdown requested");
                        requested = true;
                        handle.request();
                    } else {
                        tracing::warn!("second signal: exiting without cleanup");
                        last_words();
                        std::process::exit(130);
                    }
                }
            })?;
        Ok(shutdown)
    }

    pub fn request(&self) {
        self.requested.store(true, Ordering::SeqCst);
        if let Ok(mut trigger) = self.trigger.lock() {
            trigger.take();
        }
    }

    pub fn is_requested(&self) -> bool {
        self.requested.load(Ordering::SeqCst)
    }

    /// Resolves once shutdown is requested.
    pub async fn wait(&self) {
        // recv() fails as soon as the channel is closed; no message is ever sent.
        let _ = self.closed.recv().await;
    }
}

impl Default for Shutdown {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn request_wakes_every_waiter() {
        let shutdown = Shutdown::new();
        let waiters: Vec<_> = (0..3)
            .map(|_| {
                let handle = shutdown.clone();
                std::thread::spawn(move || smol::block_on(handle.wait()))
            })
            .collect();
        assert!(!shutdown.is_requested());
        shutdown.request();
        for waiter in waiters {
            waiter.join().unwrap();
        }
        assert!(shutdown.is_requested());
    }
}
