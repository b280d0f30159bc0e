//! Finding servos: ping every id at one baud rate (or each one the servos support) and ask the
//! ones that answer for model and firmware.

use std::time::Duration;

use anyhow::Result;

use crate::{
    args::PortArgs,
    arm::{identify, open_bus, ServoInfo},
    bus::{BusConfig, BusError, ServoBus},
    protocol::registers::BAUD_RATES,
};

#[derive(Debug, Clone, clap::Args)]
pub struct ScanArgs {
    #[command(flatten)]
    pub port: PortArgs,
    /// Try every baud rate the servos support, not only --baud.
    #[arg(long)]
    pub all_bauds: bool,
    /// Highest id to ping.
    #[arg(long, default_value_t = 252)]
    pub max_id: u8,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct Found {
    pub baud: u32,
    pub servos: Vec<ServoInfo>,
}

/// Pings ids 1..=max_id on `bus` (set up by `probe_config`): a missing id costs one short
/// timeout, not the default retries. A servo whose answer came after that short wait (an emulator
/// on a busy machine) is there all the same: it is identified again with `patient` settings.
pub fn find_servos(
    bus: &mut ServoBus,
    max_id: u8,
    patient: BusConfig,
) -> Result<Vec<ServoInfo>, BusError> {
    let mut found = Vec::new();
    for id in 1..=max_id.min(crate::protocol::MAX_ID) {
        match bus.ping(id) {
            Ok(_) => found.push(identify_answering(bus, id)?),
            Err(BusError::NoAnswer { .. }) => {}
            Err(error) => return Err(error),
        }
    }
    let late = bus.take_late_answerers(patient.slack)?;
    let missed: Vec<u8> = late
        .into_iter()
        .filter(|id| found.iter().all(|servo| servo.id != *id))
        .collect();
    if !missed.is_empty() {
        tracing::info!(
            ?missed,
            "servos answered late; asking them again, patiently"
        );
        let probe = *bus.config();
        bus.set_config(patient);
        for id in missed {
            found.push(identify_answering(bus, id)?);
        }
        bus.set_config(probe);
        found.sort_by_key(|servo| servo.id);
    }
    Ok(found)
}

/// Reads model and firmware of a servo that answered its ping. The probe's bus settings have no
/// retries (an absent id must cost little), so a lost reply here is read again rather than
/// ending the scan.
fn identify_answering(bus: &mut ServoBus, id: u8) -> Result<ServoInfo, BusError> {
    const ATTEMPTS: u32 = 4;
    let mut attempt = 1;
    loop {
        match identify(bus, id) {
            Err(BusError::NoAnswer { .. }) if attempt < ATTEMPTS => attempt += 1,
            result => return result,
        }
    }
}

/// Bus settings for probing: no retries and a short wait (an absent id never answers).
pub fn probe_config(base: BusConfig) -> BusConfig {
    BusConfig {
        retries: 0,
        slack: Duration::from_millis(3).min(base.slack),
        ..base
    }
}

pub fn run(args: &ScanArgs) -> Result<()> {
    let bauds: Vec<u32> = if args.all_bauds {
        BAUD_RATES.iter().map(|(_, baud)| *baud).collect()
    } else {
        vec![args.port.baud]
    };
    let mut results = Vec::new();
    for baud in bauds {
        let config = probe_config(BusConfig {
            baud,
            ..args.port.bus_config()
        });
        let mut bus = open_bus(&args.port.port, config)?;
        let servos = find_servos(&mut bus, args.max_id, args.port.bus_config())?;
        let stats = bus.stats();
        if stats.checksum_errors > 0 {
            tracing::warn!(
                baud,
                checksum_errors = stats.checksum_errors,
                "corrupted answers during the scan"
            );
        }
        results.push(Found { baud, servos });
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&results)?);
        return Ok(());
    }
    for found in &results {
        println!("{} baud: {} servo(s)", found.baud, found.servos.len());
        for servo in &found.servos {
            let model = if servo.model == i32::from(crate::protocol::registers::STS3215_MODEL) {
                "STS3215".to_owned()
            } else {
                format!("model {}", servo.model)
            };
            println!(
                "  id {:>3}  {model}  firmware {}.{}",
                servo.id, servo.firmware.0, servo.firmware.1
            );
        }
    }
    Ok(())
}
