//! The driver's /diagnostics: one status for the bus and one per servo, in the shape the ROS
//! diagnostics tools (rqt_robot_monitor, diagnostic_aggregator) expect. Pure: built from a report.

use so101_core::robot::{JOINT_COUNT, JOINT_NAMES};
use so101_msgs::diagnostic_msgs::{DiagnosticStatus, KeyValue};

use crate::{arm::Telemetry, bus::BusStats, protocol::ServoErrors, safety::SafetyCounters};

/// Temperature from which a servo is reported as running hot (its own limit is 70 deg C).
const HOT_CELSIUS: i32 = 55;
/// Error bits that mean the servo protects itself (it may cut torque).
const SERIOUS_ERRORS: u8 = ServoErrors::VOLTAGE
    | ServoErrors::ANGLE_SENSOR
    | ServoErrors::OVERHEAT
    | ServoErrors::OVERCURRENT;

/// One servo as the control loop last saw it.
#[derive(Debug, Clone, Copy, Default)]
pub struct ServoReport {
    pub id: u8,
    pub answering: bool,
    pub errors: ServoErrors,
    pub position_ticks: Option<i32>,
    pub telemetry: Option<Telemetry>,
}

/// Everything /diagnostics tells.
#[derive(Debug, Clone)]
pub struct DriverReport {
    pub node_name: String,
    pub port: String,
    pub connected: bool,
    /// What is wrong right now, in words.
    pub problem: Option<String>,
    pub leader: bool,
    pub torque_on: bool,
    pub cycle_rate: f64,
    pub requested_rate: Option<f64>,
    pub cycles: u64,
    pub lateness_p99_us: u32,
    pub overruns: u64,
    pub failed_cycles: u64,
    pub reconnects: u64,
    pub bus: BusStats,
    pub commands_accepted: u64,
    pub commands_rejected: u64,
    pub safety: SafetyCounters,
    pub dropped_messages: u64,
    pub servos: [ServoReport; JOINT_COUNT],
}

fn value(key: &str, value: impl ToString) -> KeyValue {
    KeyValue {
        key: key.to_owned(),
        value: value.to_string(),
    }
}

pub fn statuses(report: &DriverReport) -> Vec<DiagnosticStatus> {
    let mut statuses = vec![bus_status(report)];
    for (joint, servo) in report.servos.iter().enumerate() {
        statuses.push(servo_status(report, joint, servo));
    }
    statuses
}

fn bus_status(report: &DriverReport) -> DiagnosticStatus {
    let (level, message) = match (&report.problem, report.connected) {
        (Some(problem), _) => (DiagnosticStatus::ERROR, problem.clone()),
        (None, false) => (DiagnosticStatus::ERROR, "not connected".to_owned()),
        (None, true) => match report.requested_rate {
            Some(rate) if report.cycle_rate > 0.0 && report.cycle_rate < 0.9 * rate => (
                DiagnosticStatus::WARN,
                format!(
                    "running at {:.0} cycles/s, below the requested {rate:.0}",
                    report.cycle_rate
                ),
            ),
            _ => (DiagnosticStatus::OK, "running".to_owned()),
        },
    };
    let bus = &report.bus;
    let s = &report.safety;
    DiagnosticStatus {
        level,
        name: format!("{}: bus", report.node_name),
        message,
        hardware_id: report.port.clone(),
        values: vec![
            value("connected", report.connected),
            value("mode", if report.leader { "leader" } else { "follower" }),
            value("torque_on", report.torque_on),
            value("cycle_rate_hz", format!("{:.1}", report.cycle_rate)),
            value(
                "requested_rate_hz",
                report
                    .requested_rate
                    .map_or("max".to_owned(), |rate| format!("{rate:.1}")),
            ),
            value("cycles", report.cycles),
            value("cycle_lateness_p99_us", report.lateness_p99_us),
            value("overruns", report.overruns),
            value("failed_cycles", report.failed_cycles),
            value("reconnects", report.reconnects),
            value("transactions", bus.transactions),
            value("timeouts", bus.timeouts),
            value("retries", bus.retries),
            value("failed_transactions", bus.failures),
            value("checksum_errors", bus.checksum_errors),
            value("garbage_bytes", bus.garbage_bytes),
            value("stale_replies", bus.stale_replies),
            value("accepted_commands", report.commands_accepted),
            value("rejected_commands", report.commands_rejected),
            value("clamped_targets", s.clamped_targets),
            value("limited_steps", s.limited_steps),
            value("watchdog_holds", s.watchdog_holds),
            value("held_out_of_range", s.held_out_of_range),
            value("implausible_readings", s.implausible_readings),
            value("dropped_messages", report.dropped_messages),
        ],
    }
}

fn servo_status(report: &DriverReport, joint: usize, servo: &ServoReport) -> DiagnosticStatus {
    let mut problems = Vec::new();
    let mut level = DiagnosticStatus::OK;
    if !report.connected {
        level = DiagnosticStatus::STALE;
        problems.push("bus not connected".to_owned());
    } else if !servo.answering {
        level = DiagnosticStatus::ERROR;
        problems.push("not answering".to_owned());
    }
    if !servo.errors.is_empty() {
        let serious = servo.errors.0 & SERIOUS_ERRORS != 0;
        level = level.max(if serious {
            DiagnosticStatus::ERROR
        } else {
            DiagnosticStatus::WARN
        });
        problems.push(format!("error bits: {}", servo.errors.names().join(", ")));
    }
    if let Some(telemetry) = servo.telemetry.filter(|t| t.temperature >= HOT_CELSIUS) {
        level = level.max(DiagnosticStatus::WARN);
        problems.push(format!("hot: {} deg C", telemetry.temperature));
    }
    let mut values = vec![
        value("id", servo.id),
        value("answering", servo.answering),
        value("error_bits", format!("0x{:02X}", servo.errors.0)),
        value(
            "position_ticks",
            servo
                .position_ticks
                .map_or(String::new(), |t| t.to_string()),
        ),
    ];
    if let Some(t) = servo.telemetry {
        values.extend([
            value("voltage_v", format!("{:.1}", t.voltage)),
            value("temperature_c", t.temperature),
            value("load_percent", format!("{:.1}", f64::from(t.load) / 10.0)),
            value("current_ma", format!("{:.0}", t.current_ma)),
            value("velocity_ticks_per_s", t.velocity),
            value("moving", t.moving),
        ]);
    }
    DiagnosticStatus {
        level,
        name: format!(
            "{}: {} (id {})",
            report.node_name, JOINT_NAMES[joint], servo.id
        ),
        message: if problems.is_empty() {
            "ok".to_owned()
        } else {
            problems.join("; ")
        },
        hardware_id: format!("{} id {}", report.port, servo.id),
        values,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report() -> DriverReport {
        DriverReport {
            node_name: "so101_feetech_driver".into(),
            port: "/dev/ttyACM0".into(),
            connected: true,
            problem: None,
            leader: false,
            torque_on: true,
            cycle_rate: 200.0,
            requested_rate: Some(200.0),
            cycles: 1000,
            lateness_p99_us: 80,
            overruns: 0,
            failed_cycles: 0,
            reconnects: 0,
            bus: BusStats::default(),
            commands_accepted: 3,
            commands_rejected: 1,
            safety: SafetyCounters::default(),
            dropped_messages: 0,
            servos: std::array::from_fn(|joint| ServoReport {
                id: joint as u8 + 1,
                answering: true,
                ..ServoReport::default()
            }),
        }
    }

    #[test]
    fn a_healthy_arm_is_ok_everywhere() {
        let statuses = statuses(&report());
        assert_eq!(statuses.len(), 1 + JOINT_COUNT);
        assert!(statuses.iter().all(|s| s.level == DiagnosticStatus::OK));
        assert_eq!(statuses[6].name, "so101_feetech_driver: gripper (id 6)");
    }

    #[test]
    fn problems_raise_the_level_and_say_what_is_wrong() {
        let mut report = report();
        report.servos[2].answering = false;
        report.servos[4].errors = ServoErrors(ServoErrors::OVERLOAD);
        report.servos[5].telemetry = Some(Telemetry {
            temperature: 61,
            ..Telemetry::default()
        });
        report.cycle_rate = 120.0;
        let statuses = statuses(&report);
        assert_eq!(statuses[0].level, DiagnosticStatus::WARN);
        assert!(statuses[0].message.contains("below the requested"));
        assert_eq!(statuses[3].level, DiagnosticStatus::ERROR);
        assert_eq!(statuses[3].message, "not answering");
        assert_eq!(statuses[5].level, DiagnosticStatus::WARN);
        assert!(statuses[5].message.contains("overload"));
        assert!(statuses[6].message.contains("hot"));
        report.connected = false;
        report.problem = Some("serial port lost".into());
        let statuses = self::statuses(&report);
        assert_eq!(statuses[0].level, DiagnosticStatus::ERROR);
        assert_eq!(statuses[1].level, DiagnosticStatus::STALE);
    }
}
