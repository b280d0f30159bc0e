//! A udev rule for the arms' USB serial adapters: stable names (/dev/so101_follower,
//! /dev/so101_leader) by the adapter's USB serial number, access for the dialout group instead of
//! a world-writable device, and the FTDI latency timer at 1 ms. The rule text is pure; `run`
//! prints it or writes it.

use std::{
    io::Write,
    path::{Path, PathBuf},
};

use anyhow::{bail, Context, Result};

/// The file the rules go to (late, so the names and modes here win).
pub const RULES_FILE: &str = "99-so101.rules";
/// Where udev reads local rules.
pub const DEFAULT_RULES_DIR: &str = "/etc/udev/rules.d";
pub const FOLLOWER_NAME: &str = "so101_follower";
pub const LEADER_NAME: &str = "so101_leader";
/// Longest serial number accepted (USB string descriptors are at most 126 characters).
const MAX_SERIAL_LEN: usize = 126;

#[derive(Debug, Clone, clap::Args)]
pub struct InstallUdevArgs {
    /// USB serial number of the follower arm's adapter (ATTRS{serial}; find-port prints it).
    #[arg(long, value_name = "SERIAL")]
    pub follower_serial: String,
    /// USB serial number of the leader arm's adapter.
    #[arg(long, value_name = "SERIAL")]
    pub leader_serial: Option<String>,
    /// Print the rules (the default).
    #[arg(long, conflicts_with = "install")]
    pub print: bool,
    /// Write the rules to --rules-dir/99-so101.rules (needs root for /etc).
    #[arg(long)]
    pub install: bool,
    /// Directory of the installed rules.
    #[arg(long, default_value = DEFAULT_RULES_DIR, requires = "install")]
    pub rules_dir: PathBuf,
}

#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum SerialError {
    #[error("the serial number is empty")]
    Empty,
    #[error("the serial number is longer than {MAX_SERIAL_LEN} characters")]
    TooLong,
    #[error("the serial number {0:?} has characters other than letters, digits, '-', '_', '.' and ':' (udev would read them as patterns or quotes)")]
    BadCharacter(String),
    #[error(
        "the follower and the leader have the same serial number {0:?}: each adapter needs its own"
    )]
    Same(String),
}

/// A USB serial number as udev's ATTRS{serial} sees it: letters, digits and `-_.:` only, so it
/// can neither end the quoted value nor act as a glob.
pub fn check_serial(serial: &str) -> Result<(), SerialError> {
    if serial.is_empty() {
        return Err(SerialError::Empty);
    }
    if serial.len() > MAX_SERIAL_LEN {
        return Err(SerialError::TooLong);
    }
    if !serial
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.' | ':'))
    {
        return Err(SerialError::BadCharacter(serial.to_owned()));
    }
    Ok(())
}

/// The rules for a follower adapter and optionally a leader's.
pub fn rules_text(
    follower_serial: &str,
    leader_serial: Option<&str>,
) -> Result<String, SerialError> {
    check_serial(follower_serial)?;
    if let Some(leader) = leader_serial {
        check_serial(leader)?;
        if leader == follower_serial {
            return Err(SerialError::Same(leader.to_owned()));
        }
    }
    let mut text = String::from(
        "# SO-101 arms: servo-bus USB serial adapters (written by so101_feetech_driver install-udev).\n\
         # Each adapter is named by its USB serial number (udevadm info --attribute-walk --name=/dev/ttyACM0\n\
         # shows ATTRS{serial}); members of the dialout group may open it.\n",
    );
    let mut arms = vec![(FOLLOWER_NAME, follower_serial)];
    if let Some(leader) = leader_serial {
        arms.push((LEADER_NAME, leader));
    }
    for (name, serial) in &arms {
        text.push_str(&format!(
            "SUBSYSTEM==\"tty\", ATTRS{{serial}}==\"{serial}\", SYMLINK+=\"{name}\", GROUP=\"dialout\", MODE=\"0660\"\n"
        ));
    }
    text.push_str(
        "# FTDI-style adapters buffer replies for 16 ms by default, which caps the bus near 60\n\
         # round trips a second: lower their latency timer to 1 ms. The SO-101 boards' usual\n\
         # CH343/CH340 chips (1a86:55d3, 1a86:7523) have no such timer; the kernel exposes none.\n",
    );
    for (_, serial) in &arms {
        text.push_str(&format!(
            "ACTION==\"add\", SUBSYSTEM==\"usb-serial\", DRIVER==\"ftdi_sio\", ATTRS{{serial}}==\"{serial}\", ATTR{{latency_timer}}=\"1\"\n"
        ));
    }
    Ok(text)
}

/// Writes the rules to `dir`/99-so101.rules (a new file renamed into place, mode 0644).
pub fn install(dir: &Path, text: &str) -> Result<PathBuf> {
    if !dir.is_dir() {
        bail!("{} is not a directory", dir.display());
    }
    let path = dir.join(RULES_FILE);
    let temporary = dir.join(format!(".{RULES_FILE}.tmp{}", std::process::id()));
    let write = || -> std::io::Result<()> {
        let mut file = std::fs::File::create(&temporary)?;
        file.write_all(text.as_bytes())?;
        file.sync_all()?;
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&temporary, std::fs::Permissions::from_mode(0o644))?;
        std::fs::rename(&temporary, &path)
    };
    if let Err(error) = write() {
        let _ = std::fs::remove_file(&temporary);
        let hint = if error.kind() == std::io::ErrorKind::PermissionDenied {
            " (run it with sudo)"
        } else {
            ""
        };
        return Err(error).with_context(|| format!("cannot write {}{hint}", path.display()));
    }
    Ok(path)
}

/// What to do after the rules are written.
pub fn next_steps(path: &Path, leader: bool) -> String {
    let names = if leader {
        format!("/dev/{FOLLOWER_NAME} and /dev/{LEADER_NAME}")
    } else {
        format!("/dev/{FOLLOWER_NAME}")
    };
    format!(
        "Wrote {}.\nLoad the rules and apply them to the plugged-in adapters:\n  \
         sudo udevadm control --reload-rules && sudo udevadm trigger\n\
         Let your user open the ports (then log out and in again):\n  \
         sudo usermod -aG dialout $USER\n\
         Then unplug and replug the adapters: {names} appear.",
        path.display()
    )
}

/// The `install-udev` subcommand.
pub fn run(args: &InstallUdevArgs) -> Result<()> {
    let text = rules_text(&args.follower_serial, args.leader_serial.as_deref())?;
    if args.install {
        let path = install(&args.rules_dir, &text)?;
        println!("{}", next_steps(&path, args.leader_serial.is_some()));
    } else {
        print!("{text}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_naming_rule_per_arm_with_group_access() {
        let text = rules_text("5A46082351", Some("5A46082352")).unwrap();
        let rules: Vec<&str> = text.lines().filter(|line| !line.starts_with('#')).collect();
        assert_eq!(
            rules[0],
            r#"SUBSYSTEM=="tty", ATTRS{serial}=="5A46082351", SYMLINK+="so101_follower", GROUP="dialout", MODE="0660""#
        );
        assert_eq!(
            rules[1],
            r#"SUBSYSTEM=="tty", ATTRS{serial}=="5A46082352", SYMLINK+="so101_leader", GROUP="dialout", MODE="0660""#
        );
        assert_eq!(
            rules[2],
            r#"ACTION=="add", SUBSYSTEM=="usb-serial", DRIVER=="ftdi_sio", ATTRS{serial}=="5A46082351", ATTR{latency_timer}="1""#
        );
        assert_eq!(rules.len(), 4);
        assert!(!text.contains("0666"));
        assert!(text.contains("CH343"));
        assert!(text.contains("1a86:55d3"));
    }

    #[test]
    fn the_leader_is_optional() {
        let text = rules_text("A1", None).unwrap();
        assert!(text.contains("so101_follower"));
        assert!(!text.contains("so101_leader"));
        assert_eq!(text.lines().filter(|l| !l.starts_with('#')).count(), 2);
    }

    #[test]
    fn invalid_serials_are_refused() {
        assert_eq!(rules_text("", None), Err(SerialError::Empty));
        assert!(matches!(
            rules_text("A\"B", None),
            Err(SerialError::BadCharacter(_))
        ));
        assert!(matches!(
            rules_text("A*", None),
            Err(SerialError::BadCharacter(_))
        ));
        assert!(matches!(
            rules_text("A B", None),
            Err(SerialError::BadCharacter(_))
        ));
        assert!(matches!(
            rules_text("ok", Some("bad\n")),
            Err(SerialError::BadCharacter(_))
        ));
        assert_eq!(
            rules_text("S1", Some("S1")),
            Err(SerialError::Same("S1".into()))
        );
        assert_eq!(
            rules_text(&"x".repeat(MAX_SERIAL_LEN + 1), None),
            Err(SerialError::TooLong)
        );
        assert!(rules_text("0001:ab-CD_9.x", None).is_ok());
    }

    #[test]
    fn install_writes_the_file_and_replaces_an_old_one() {
        let dir = tempfile::tempdir().unwrap();
        let path = install(dir.path(), "old\n").unwrap();
        assert_eq!(path, dir.path().join(RULES_FILE));
        let path = install(dir.path(), "new\n").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new\n");
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&path).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o644);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        assert!(install(&dir.path().join("missing"), "x").is_err());
        let steps = next_steps(&path, true);
        assert!(steps.contains("udevadm control --reload-rules && sudo udevadm trigger"));
        assert!(steps.contains("usermod -aG dialout"));
        assert!(steps.contains("/dev/so101_leader"));
    }
}
