//! A scripted source for tests and demonstrations: a JSON-lines file of timed inputs, each line one
//! of
//!
//! ```text
//! {"at": 0.5, "jog": [1, 0, 0, 0, 0, 0]}      velocity request (in the current mode) from 0.5 s on
//! {"at": 2.0, "targets": [0, 0.3, 0, 0, 0, 1]} absolute joint targets from 2.0 s on
//! {"at": 3.0, "lost": true}                   the device disappears from 3.0 s on
//! {"at": 3.5, "control": "success"}           one control at 3.5 s
//! ```
//!
//! `at` is seconds on the node's clock from the first control period; lines must be in time order.
//! Controls: start, stop, toggle_recording, success, failure, rerecord, reset, toggle_mode, halt,
//! quit.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::Deserialize;
use so101_core::robot::JOINT_COUNT;

use super::{Reading, Request, Source, Tick};
use crate::{controls::Control, motion::Jog};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Line {
    at: f64,
    jog: Option<[f64; JOINT_COUNT]>,
    targets: Option<[f64; JOINT_COUNT]>,
    lost: Option<bool>,
    control: Option<String>,
}

#[derive(Debug, Clone, PartialEq)]
enum Step {
    Request(Request),
    Control(Control),
}

/// The timed steps of a script.
#[derive(Debug)]
pub struct Scripted {
    steps: Vec<(f64, Step)>,
    next: usize,
    start: Option<f64>,
    request: Request,
}

fn control_named(name: &str) -> Option<Control> {
    Some(match name {
        "start" => Control::Start {
            task: None,
            seed: None,
        },
        "stop" => Control::Stop,
        "toggle_recording" => Control::ToggleRecording,
        "success" => Control::MarkSuccess,
        "failure" => Control::MarkFailure,
        "rerecord" => Control::Rerecord,
        "reset" => Control::ResetSim,
        "toggle_mode" => Control::ToggleMode,
        "halt" => Control::Halt,
        "quit" => Control::Quit,
        _ => return None,
    })
}

impl Scripted {
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read the script {}", path.display()))?;
        Self::parse(&text).with_context(|| format!("script {}", path.display()))
    }

    pub fn parse(text: &str) -> Result<Self> {
        let mut steps = Vec::new();
        let mut last_at = f64::NEG_INFINITY;
        for (number, raw) in text.lines().enumerate() {
            let number = number + 1;
            if raw.trim().is_empty() || raw.trim_start().starts_with('#') {
                continue;
            }
            let line: Line = serde_json::from_str(raw)
                .with_context(|| format!("line {number} is not a script line"))?;
            if !line.at.is_finite() || line.at < last_at {
                bail!("line {number}: \"at\" must be finite and in time order");
            }
            last_at = line.at;
            let step = match (line.jog, line.targets, line.lost, line.control) {
                (Some(axes), None, None, None) if axes.iter().all(|v| v.is_finite()) => {
                    Step::Request(Request::Jog(Jog { axes }))
                }
                (None, Some(targets), None, None) if targets.iter().all(|v| v.is_finite()) => {
                    Step::Request(Request::Targets(targets))
                }
                (None, None, Some(true), None) => Step::Request(Request::Lost),
                (None, None, None, Some(name)) => Step::Control(
                    control_named(&name)
                        .with_context(|| format!("line {number}: unknown control {name:?}"))?,
                ),
                _ => bail!(
                    "line {number}: give exactly one of jog, targets (6 finite numbers each), lost: true, control"
                ),
            };
            steps.push((line.at, step));
        }
        Ok(Self {
            steps,
            next: 0,
            start: None,
            request: Request::Jog(Jog::STILL),
        })
    }
}

impl Source for Scripted {
    fn read(&mut self, tick: &Tick) -> Reading {
        let start = *self.start.get_or_insert(tick.now);
        let elapsed = tick.now - start;
        let mut controls = Vec::new();
        while let Some((at, step)) = self.steps.get(self.next) {
            if *at > elapsed + 1e-9 {
                break;
            }
            match step {
                Step::Request(request) => self.request = request.clone(),
                Step::Control(control) => controls.push(control.clone()),
            }
            self.next += 1;
        }
        Reading {
            request: self.request.clone(),
            controls,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tick(now: f64) -> Tick {
        Tick {
            now,
            cartesian: false,
            scene: crate::input::Scene::default(),
        }
    }

    #[test]
    fn steps_take_effect_at_their_time_and_controls_fire_once() {
        let mut script = Scripted::parse(
            r#"{"at": 0.0, "jog": [1, 0, 0, 0, 0, 0]}
# a comment
{"at": 1.0, "control": "success"}
{"at": 1.0, "targets": [0, 0.5, 0, 0, 0, 1]}
{"at": 2.0, "lost": true}
"#,
        )
        .unwrap();
        let first = script.read(&tick(10.0));
        assert_eq!(
            first.request,
            Request::Jog(Jog {
                axes: [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            })
        );
        assert!(script.read(&tick(10.5)).controls.is_empty());
        let at_one = script.read(&tick(11.0));
        assert_eq!(at_one.controls, vec![Control::MarkSuccess]);
        assert_eq!(
            at_one.request,
            Request::Targets([0.0, 0.5, 0.0, 0.0, 0.0, 1.0])
        );
        assert!(script.read(&tick(11.5)).controls.is_empty());
        assert_eq!(script.read(&tick(12.5)).request, Request::Lost);
    }

    #[test]
    fn bad_scripts_name_the_line() {
        for (text, words) in [
            (r#"{"at": 1, "jog": [1, 0]}"#, "line 1"),
            (r#"{"at": 1, "control": "dance"}"#, "unknown control"),
            (
                "{\"at\": 2, \"lost\": true}\n{\"at\": 1, \"lost\": true}",
                "time order",
            ),
            (
                r#"{"at": 1, "jog": [0,0,0,0,0,0], "lost": true}"#,
                "exactly one",
            ),
            ("not json", "line 1"),
        ] {
            let error = format!("{:#}", Scripted::parse(text).unwrap_err());
            assert!(error.contains(words), "{text}: {error}");
        }
    }
}
