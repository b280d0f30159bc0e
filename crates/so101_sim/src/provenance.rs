//! What an episode was simulated with, as JSON: the servo model and its parameters, the
//! randomization ranges and the episode's draw. The sim node publishes it on /sim/episode (the
//! recorder keeps it in the bag's metadata); the in-process envs return it in their info, so a
//! dataset says what it was made on.

use serde_json::{json, Value};

use crate::env::TaskEnv;

/// The settings of `env`'s current episode.
pub fn episode_settings(env: &TaskEnv) -> Value {
    let servos = env.world().servos();
    let servo_params = servos
        .params()
        .and_then(|params| serde_json::from_str::<Value>(&params.to_json()).ok())
        .unwrap_or(Value::Null);
    json!({
        "servo_model": servos.choice().name(),
        "servo_params": servo_params,
        "randomization": env
            .randomization()
            .and_then(|config| serde_json::to_value(config).ok())
            .unwrap_or(Value::Null),
        "draw": env
            .draw()
            .and_then(|draw| serde_json::to_value(draw).ok())
            .unwrap_or(Value::Null),
    })
}
