//! Logging: `tracing` to stderr, and the stack's own events mirrored to /rosout once a node exists,
//! so `ros2 topic echo /rosout` and rqt_console show what a node says.

use std::{io::IsTerminal, sync::OnceLock};

use ros2_client::{
    log::LogLevel,
    {NodeLoggingHandle, RosoutRaw},
};
use tracing::{field::Visit, Level};
use tracing_subscriber::{layer::Context, prelude::*, EnvFilter, Layer};

/// Default filter: our crates at info, the DDS libraries only when something is wrong.
const DEFAULT_FILTER: &str = "info,rustdds=error,ros2_client=warn,ros2_client::distributions=error";

static ROSOUT: OnceLock<NodeLoggingHandle> = OnceLock::new();

/// Installs the subscriber; `RUST_LOG` overrides the default filter. Safe to call more than once.
pub fn init() {
    super::crash::install();
    let filter =
        EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(DEFAULT_FILTER));
    let _ = tracing_subscriber::registry()
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(std::io::stderr)
                .with_ansi(std::io::stderr().is_terminal())
                .with_filter(filter),
        )
        .with(RosoutLayer.with_filter(tracing_subscriber::filter::LevelFilter::INFO))
        .try_init();
}

/// A binary's exit status from its run: failure with the error chain logged, or success.
pub fn exit_code(result: anyhow::Result<()>) -> std::process::ExitCode {
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(error) => {
            tracing::error!("{error:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// From now on, events of the stack's crates are also published on /rosout through `handle`.
pub fn attach_rosout(handle: NodeLoggingHandle) {
    let _ = ROSOUT.set(handle);
}

struct RosoutLayer;

impl<S: tracing::Subscriber> Layer<S> for RosoutLayer {
    fn on_event(&self, event: &tracing::Event<'_>, _context: Context<'_, S>) {
        let metadata = event.metadata();
        // Only our own crates: ros2-client logs its own rosout publishing through tracing, and
        // mirroring that back would loop.
        if !metadata.target().starts_with("so101") {
            return;
        }
        let Some(handle) = ROSOUT.get() else { return };
        let mut text = MessageText::default();
        event.record(&mut text);
        handle.rosout_raw(
            ros2_client::builtin_interfaces::Time::now(),
            level_from_tracing(*metadata.level()),
            handle.base_name(),
            &text.0,
            metadata.file().unwrap_or(""),
            metadata.module_path().unwrap_or(""),
            metadata.line().unwrap_or(0),
        );
    }
}

fn level_from_tracing(level: Level) -> LogLevel {
    match level {
        Level::ERROR => LogLevel::Error,
        Level::WARN => LogLevel::Warn,
        Level::INFO => LogLevel::Info,
        Level::DEBUG | Level::TRACE => LogLevel::Debug,
    }
}

/// The event's message followed by its other fields as `key=value`.
#[derive(Default)]
struct MessageText(String);

impl Visit for MessageText {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0.insert_str(0, &format!("{value:?}"));
        } else {
            self.0.push_str(&format!(" {}={value:?}", field.name()));
        }
    }

    fn record_str(&mut self, field: &tracing::field::Field, value: &str) {
        if field.name() == "message" {
            self.0.insert_str(0, value);
        } else {
            self.0.push_str(&format!(" {}={value}", field.name()));
        }
    }
}
