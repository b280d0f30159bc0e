//! The emulator over a real pty, driven as a client would: plain file I/O on the slave path.

use std::{
    fs::{File, OpenOptions},
    io::{Read, Write},
    os::{fd::AsFd, unix::fs::OpenOptionsExt},
    path::Path,
    time::{Duration, Instant},
};

use nix::{
    fcntl::OFlag,
    poll::{poll, PollFd, PollFlags, PollTimeout},
};
use so101_feetech_driver::protocol::{
    decode_status, encode_instruction, registers as reg, FrameError, Instruction, PacketReader,
    StatusPacket, BROADCAST_ID,
};
use so101_servo_emulator::{Emulator, EmulatorConfig, Timing};

const PATIENCE: Duration = Duration::from_millis(500);

fn start(config: EmulatorConfig) -> Emulator {
    Emulator::start(config).expect("the emulator starts")
}

fn open(path: &Path) -> File {
    OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags((OFlag::O_NOCTTY | OFlag::O_NONBLOCK).bits())
        .open(path)
        .expect("the pty opens")
}

fn send(port: &mut File, id: u8, instruction: Instruction) {
    let packet = encode_instruction(id, &instruction).expect("a valid instruction");
    port.write_all(&packet).expect("the request is written");
}

/// Frames received until `count` have arrived or `timeout` passes.
fn receive(port: &mut File, count: usize, timeout: Duration) -> Vec<Result<Vec<u8>, FrameError>> {
    let deadline = Instant::now() + timeout;
    let mut reader = PacketReader::new();
    let mut frames = Vec::new();
    let mut buffer = [0u8; 512];
    while frames.len() < count {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        let millis =
            PollTimeout::try_from(left.max(Duration::from_millis(1))).expect("a short timeout");
        let mut fds = [PollFd::new(port.as_fd(), PollFlags::POLLIN)];
        if poll(&mut fds, millis).expect("poll works") == 0 {
            continue;
        }
        match port.read(&mut buffer) {
            Ok(read) => reader.push(&buffer[..read]),
            Err(error) if error.kind() == std::io::ErrorKind::WouldBlock => continue,
            Err(error) => panic!("read failed: {error}"),
        }
        frames.extend(std::iter::from_fn(|| reader.next_frame()));
    }
    frames
}

fn statuses(port: &mut File, count: usize) -> Vec<StatusPacket> {
    receive(port, count, PATIENCE)
        .into_iter()
        .map(|frame| decode_status(&frame.expect("a valid checksum")).expect("a status packet"))
        .collect()
}

fn read(port: &mut File, id: u8, register: reg::Register) -> i32 {
    send(
        port,
        id,
        Instruction::Read {
            address: register.address,
            length: register.size,
        },
    );
    let status = statuses(port, 1);
    assert_eq!(status.len(), 1, "no answer to a read of {}", register.name);
    register
        .decode(&status[0].parameters)
        .expect("as many bytes as asked")
}

fn write(port: &mut File, id: u8, register: reg::Register, value: i32) {
    send(
        port,
        id,
        Instruction::Write {
            address: register.address,
            data: register.encode(value).expect("the value fits"),
        },
    );
    assert_eq!(
        statuses(port, 1).len(),
        1,
        "no answer to a write of {}",
        register.name
    );
}

fn sync_read_positions(ids: Vec<u8>) -> Instruction {
    Instruction::SyncRead {
        address: reg::PRESENT_POSITION.address,
        length: 2,
        ids,
    }
}

#[test]
fn ping_and_model_number() {
    let emulator = start(EmulatorConfig::default());
    let mut port = open(&emulator.port_path());
    send(&mut port, 4, Instruction::Ping);
    let answer = statuses(&mut port, 1);
    assert_eq!(answer.len(), 1);
    assert_eq!((answer[0].id, answer[0].parameters.len()), (4, 0));
    assert_eq!(read(&mut port, 1, reg::MODEL_NUMBER), 777);
}

#[test]
fn a_goal_with_torque_on_moves_the_present_position_over_time() {
    let emulator = start(EmulatorConfig::default());
    let mut port = open(&emulator.port_path());
    write(&mut port, 2, reg::TORQUE_ENABLE, 1);
    write(&mut port, 2, reg::GOAL_POSITION, 3000);
    let mut previous = 2048;
    let started = Instant::now();
    while started.elapsed() < Duration::from_millis(600) {
        let present = read(&mut port, 2, reg::PRESENT_POSITION);
        assert!(
            present >= previous && present <= 3000,
            "{previous} -> {present}"
        );
        previous = present;
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(
        previous >= 2995,
        "still at {previous} after 600 ms (tau 40 ms)"
    );
}

#[test]
fn sync_read_answers_in_id_order_without_a_silent_servo() {
    let emulator = start(EmulatorConfig::default());
    let mut port = open(&emulator.port_path());
    assert_eq!(emulator.control_line("silent 3 on"), Ok("ok".into()));
    send(
        &mut port,
        BROADCAST_ID,
        sync_read_positions(vec![6, 5, 4, 3, 2, 1]),
    );
    let ids: Vec<u8> = statuses(&mut port, 6)
        .iter()
        .map(|status| status.id)
        .collect();
    assert_eq!(ids, [6, 5, 4, 2, 1]);
}

#[test]
fn dropped_and_corrupted_replies() {
    let emulator = start(EmulatorConfig::default());
    let mut port = open(&emulator.port_path());
    emulator.control_line("drop 1.0").unwrap();
    send(&mut port, 1, Instruction::Ping);
    assert!(receive(&mut port, 1, Duration::from_millis(100)).is_empty());
    emulator.control_line("clear").unwrap();
    emulator.control_line("corrupt 1").unwrap();
    send(&mut port, 1, Instruction::Ping);
    let frames = receive(&mut port, 1, PATIENCE);
    assert_eq!(frames, [Err(FrameError::Checksum { id: 1 })]);
    emulator.control_line("clear").unwrap();
    send(&mut port, 1, Instruction::Ping);
    assert_eq!(statuses(&mut port, 1).len(), 1);
}

#[test]
fn realistic_timing_makes_a_sync_read_of_six_take_the_wire_time() {
    let emulator = start(EmulatorConfig {
        timing: Timing::Realistic { baud: 1_000_000 },
        return_delay: Some(0),
        ..EmulatorConfig::default()
    });
    let mut port = open(&emulator.port_path());
    for _ in 0..3 {
        let started = Instant::now();
        send(
            &mut port,
            BROADCAST_ID,
            sync_read_positions(vec![1, 2, 3, 4, 5, 6]),
        );
        assert_eq!(statuses(&mut port, 6).len(), 6);
        let took = started.elapsed();
        assert!(took >= Duration::from_micros(620), "{took:?}");
        assert!(took < Duration::from_millis(100), "{took:?}");
    }
}

#[test]
fn unlocked_eprom_writes_persist_and_locked_ones_do_not() {
    let dir = tempfile::tempdir().unwrap();
    let state_file = dir.path().join("servos.json");
    let config = EmulatorConfig {
        state_file: Some(state_file.clone()),
        ..EmulatorConfig::default()
    };
    {
        let emulator = start(config.clone());
        let mut port = open(&emulator.port_path());
        write(&mut port, 1, reg::LOCK, 0);
        write(&mut port, 1, reg::HOMING_OFFSET, -300);
        // Saved at the write, not only when the emulator stops.
        let deadline = Instant::now() + PATIENCE;
        while !std::fs::read_to_string(&state_file).is_ok_and(|text| text.contains("\"eprom\"")) {
            assert!(Instant::now() < deadline, "state file not written");
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    {
        let emulator = start(config.clone());
        let mut port = open(&emulator.port_path());
        assert_eq!(read(&mut port, 1, reg::HOMING_OFFSET), -300);
        assert_eq!(
            read(&mut port, 1, reg::LOCK),
            1,
            "Lock is RAM: locked again at power-up"
        );
        write(&mut port, 1, reg::HOMING_OFFSET, 500);
        assert_eq!(read(&mut port, 1, reg::HOMING_OFFSET), 500);
    }
    let emulator = start(config);
    let mut port = open(&emulator.port_path());
    assert_eq!(read(&mut port, 1, reg::HOMING_OFFSET), -300);
}

#[test]
fn hangup_breaks_the_old_fd_and_the_link_comes_back_on_a_new_pty() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ttySO101");
    let emulator = start(EmulatorConfig {
        link: Some(link.clone()),
        ..EmulatorConfig::default()
    });
    assert_eq!(emulator.port_path(), link);
    let first_target = std::fs::read_link(&link).unwrap();
    let mut port = open(&link);
    send(&mut port, 1, Instruction::Ping);
    assert_eq!(statuses(&mut port, 1).len(), 1);

    assert_eq!(emulator.control_line("hangup 0.3"), Ok("ok".into()));
    let mut fds = [PollFd::new(port.as_fd(), PollFlags::POLLIN)];
    poll(&mut fds, PollTimeout::from(100u8)).unwrap();
    assert!(fds[0]
        .revents()
        .unwrap()
        .intersects(PollFlags::POLLHUP | PollFlags::POLLERR));
    let mut buffer = [0u8; 8];
    assert!(matches!(port.read(&mut buffer), Err(_) | Ok(0)));
    assert!(
        std::fs::symlink_metadata(&link).is_err(),
        "link removed while unplugged"
    );

    let deadline = Instant::now() + Duration::from_secs(3);
    while std::fs::symlink_metadata(&link).is_err() {
        assert!(Instant::now() < deadline, "the link did not come back");
        std::thread::sleep(Duration::from_millis(10));
    }
    assert_ne!(std::fs::read_link(&link).unwrap(), first_target);
    let mut port = open(&link);
    send(&mut port, 1, Instruction::Ping);
    assert_eq!(statuses(&mut port, 1).len(), 1);
    drop(emulator);
    assert!(
        std::fs::symlink_metadata(&link).is_err(),
        "link removed at stop"
    );
}

#[test]
fn dump_reports_every_slot_and_plug_attaches_a_servo() {
    let emulator = start(EmulatorConfig {
        ids: vec![1, 1],
        plugged: Some(vec![true, false]),
        ..EmulatorConfig::default()
    });
    let mut port = open(&emulator.port_path());
    send(&mut port, 1, Instruction::Ping);
    assert_eq!(
        statuses(&mut port, 2).len(),
        1,
        "one factory servo attached"
    );
    let dump: serde_json::Value =
        serde_json::from_str(&emulator.control_line("dump").unwrap()).unwrap();
    assert_eq!(dump["slots"][1]["plugged"], false);
    assert_eq!(dump["slots"][0]["present_position"], 2048);
    assert_eq!(dump["slots"][0]["return_delay_time"], 250);
    emulator.control_line("move 1 1000").unwrap();
    assert_eq!(read(&mut port, 1, reg::PRESENT_POSITION), 1000);
    assert!(emulator
        .control_line("plug 7")
        .unwrap_err()
        .contains("no slot 7"));
}
