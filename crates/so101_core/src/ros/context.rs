//! A DDS context configured from the standard ROS 2 environment variables, which neither ros2-client
//! nor RustDDS read by themselves.

use std::net::Ipv4Addr;

use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::Context;

/// Highest domain id whose ports fit the default RTPS port mapping on Linux.
const MAX_DOMAIN_ID: u16 = 232;

#[derive(Debug, thiserror::Error)]
pub enum ContextError {
    #[error("ROS_DOMAIN_ID={0:?} is not a domain id (an integer from 0 to {MAX_DOMAIN_ID})")]
    BadDomainId(String),
    #[error("cannot create the DDS participant: {0}")]
    Dds(String),
}

/// The ROS 2 environment: `ROS_DOMAIN_ID`, and whether discovery is limited to this host
/// (`ROS_LOCALHOST_ONLY=1` from Humble, or `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` from Jazzy).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RosEnvironment {
    pub domain_id: u16,
    pub localhost_only: bool,
}

impl RosEnvironment {
    pub fn from_env() -> Result<Self, ContextError> {
        Self::from_lookup(|key| std::env::var(key).ok())
    }

    /// Reads the variables through `lookup`, so the rules are testable without touching the process
    /// environment.
    pub fn from_lookup(lookup: impl Fn(&str) -> Option<String>) -> Result<Self, ContextError> {
        let domain_id = match lookup("ROS_DOMAIN_ID").map(|value| value.trim().to_owned()) {
            None => 0,
            Some(value) if value.is_empty() => 0,
            Some(value) => value
                .parse::<u16>()
                .ok()
                .filter(|id| *id <= MAX_DOMAIN_ID)
                .ok_or(ContextError::BadDomainId(value))?,
        };
        // RustDDS cannot switch discovery off, so OFF is held to the nearest it can do: this host.
        let localhost_only = lookup("ROS_LOCALHOST_ONLY").is_some_and(|value| value.trim() == "1")
            || lookup("ROS_AUTOMATIC_DISCOVERY_RANGE").is_some_and(|value| {
                let value = value.trim();
                value.eq_ignore_ascii_case("LOCALHOST") || value.eq_ignore_ascii_case("OFF")
            });
        Ok(Self {
            domain_id,
            localhost_only,
        })
    }
}

/// Creates the DDS context for `environment`. Localhost-only restricts multicast and the advertised
/// locators to the loopback interface.
pub fn create_context(environment: &RosEnvironment) -> Result<Context, ContextError> {
    let mut builder = DomainParticipantBuilder::new(environment.domain_id);
    if environment.localhost_only {
        builder = builder.with_only_networks([Ipv4Addr::LOCALHOST]);
    }
    let participant = builder
        .build()
        .map_err(|error| ContextError::Dds(error.to_string()))?;
    Context::from_domain_participant(participant)
        .map_err(|error| ContextError::Dds(error.to_string()))
}

/// Whether this process sees no network interface but loopback (inside `scripts/isolated`): DDS
/// tests refuse to open a participant anywhere else, where multicast could leave the machine.
pub fn only_loopback() -> bool {
    std::fs::read_to_string("/proc/self/net/dev").is_ok_and(|devices| {
        devices
            .lines()
            .skip(2)
            .filter_map(|line| line.split(':').next())
            .all(|name| name.trim() == "lo")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(vars: &[(&str, &str)]) -> Result<RosEnvironment, ContextError> {
        let vars: Vec<(String, String)> = vars
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        RosEnvironment::from_lookup(|key| {
            vars.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone())
        })
    }

    #[test]
    fn defaults_to_domain_zero_on_all_networks() {
        assert_eq!(
            env(&[]).unwrap(),
            RosEnvironment {
                domain_id: 0,
                localhost_only: false
            }
        );
        assert_eq!(env(&[("ROS_DOMAIN_ID", "")]).unwrap().domain_id, 0);
    }

    #[test]
    fn reads_domain_id_and_both_localhost_variables() {
        assert_eq!(env(&[("ROS_DOMAIN_ID", "42")]).unwrap().domain_id, 42);
        assert!(env(&[("ROS_LOCALHOST_ONLY", "1")]).unwrap().localhost_only);
        assert!(!env(&[("ROS_LOCALHOST_ONLY", "0")]).unwrap().localhost_only);
        assert!(
            env(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")])
                .unwrap()
                .localhost_only
        );
        assert!(
            env(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")])
                .unwrap()
                .localhost_only
        );
        assert!(
            !env(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")])
                .unwrap()
                .localhost_only
        );
    }

    #[test]
    fn rejects_bad_domain_ids() {
        for bad in ["-1", "233", "abc", "1.5"] {
            assert!(
                matches!(
                    env(&[("ROS_DOMAIN_ID", bad)]),
                    Err(ContextError::BadDomainId(_))
                ),
                "{bad}"
            );
        }
    }
}
