//! Which serial port is the arm's adapter, like LeRobot's `lerobot-find-port`: list the ports,
//! the user unplugs the adapter and presses Enter, list again; the port that disappeared is the
//! one. The comparison and the messages are pure (below); listing ports and the terminal are the
//! thin I/O around them.
//!
//! On Linux one adapter shows up under several names (/dev/ttyACM0 and its
//! /dev/serial/by-id/usb-... link, or a udev SYMLINK): names that led to the same device count as
//! one adapter.

use std::{
    collections::BTreeMap,
    path::{Path, PathBuf},
    time::{Duration, Instant},
};

use anyhow::{bail, Context, Result};

/// Where serial adapters appear on Linux: CDC-ACM (CH343, the SO-101 boards' usual chip), USB
/// serial (CH340, FTDI, CP210x) and udev's stable links.
pub const DEFAULT_GLOBS: [&str; 3] = ["/dev/ttyACM*", "/dev/ttyUSB*", "/dev/serial/by-id/*"];

/// How long the second listing waits for the kernel to remove the device after Enter.
const SETTLE: Duration = Duration::from_secs(1);

#[derive(Debug, Clone, clap::Args)]
pub struct FindPortArgs {
    /// Where to look for ports, a path with shell wildcards (repeatable;
    /// default: /dev/ttyACM*, /dev/ttyUSB*, /dev/serial/by-id/*).
    #[arg(long, value_name = "PATTERN")]
    pub dev_glob: Vec<String>,
}

/// One port name present at a listing, with the device it resolved to then (symlinks followed).
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct PortEntry {
    pub path: PathBuf,
    pub device: PathBuf,
}

impl PortEntry {
    /// A name that is the device node itself, not a link to it.
    fn is_device_node(&self) -> bool {
        self.path == self.device
    }
}

/// One adapter that disappeared: its device and every name it had.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Gone {
    pub device: PathBuf,
    /// The name to use: the device node (/dev/ttyACM0) when it was listed, else the first link.
    pub port: PathBuf,
    /// Its other names (by-id links, udev symlinks).
    pub aliases: Vec<PathBuf>,
}

/// What the two listings say.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// Exactly one adapter disappeared.
    Found(Gone),
    /// Nothing disappeared.
    NoneGone,
    /// More than one adapter disappeared.
    SeveralGone(Vec<Gone>),
}

/// Compares the listing before the unplug with the one after: the names that disappeared,
/// grouped by the device they led to.
pub fn compare(before: &[PortEntry], after: &[PortEntry]) -> Outcome {
    let mut by_device: BTreeMap<&Path, Vec<&PortEntry>> = BTreeMap::new();
    for entry in before {
        if !after.iter().any(|now| now.path == entry.path) {
            by_device.entry(&entry.device).or_default().push(entry);
        }
    }
    let mut gone: Vec<Gone> = by_device
        .into_iter()
        .map(|(device, mut names)| {
            names.sort();
            names.dedup();
            let primary = names
                .iter()
                .position(|entry| entry.is_device_node())
                .unwrap_or(0);
            let port = names[primary].path.clone();
            let aliases = names
                .iter()
                .enumerate()
                .filter(|(index, _)| *index != primary)
                .map(|(_, entry)| entry.path.clone())
                .collect();
            Gone {
                device: device.to_owned(),
                port,
                aliases,
            }
        })
        .collect();
    match gone.len() {
        0 => Outcome::NoneGone,
        1 => Outcome::Found(gone.remove(0)),
        _ => Outcome::SeveralGone(gone),
    }
}

/// The listing as shown to the user.
pub fn listing_text(ports: &[PortEntry]) -> String {
    if ports.is_empty() {
        return "  (no serial ports)".to_owned();
    }
    ports
        .iter()
        .map(|entry| {
            if entry.is_device_node() {
                format!("  {}", entry.path.display())
            } else {
                format!("  {} -> {}", entry.path.display(), entry.device.display())
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The answer for a found adapter (success).
pub fn found_text(gone: &Gone, usb: Option<&UsbIdentity>) -> String {
    let mut text = format!("The port of this adapter is {}", gone.port.display());
    if !gone.aliases.is_empty() {
        let names: Vec<String> = gone
            .aliases
            .iter()
            .map(|path| path.display().to_string())
            .collect();
        text.push_str(&format!("\nIt is also reachable as: {}", names.join(", ")));
    }
    if let Some(usb) = usb {
        text.push_str(&format!(
            "\nUSB adapter {}:{}, serial number {} (for `so101_feetech_driver install-udev`)",
            usb.vendor,
            usb.product,
            usb.serial
                .as_deref()
                .unwrap_or("(none: this adapter has no serial number)")
        ));
    }
    text.push_str("\nReconnect the USB cable.");
    text
}

/// Why no single port could be named (failure).
pub fn failure_text(outcome: &Outcome, after: &[PortEntry]) -> Option<String> {
    match outcome {
        Outcome::Found(_) => None,
        Outcome::NoneGone => Some(format!(
            "No port disappeared. Was the adapter's USB cable unplugged (not only the servos' \
             power)? The ports now:\n{}\nReconnect the USB cable and run find-port again.",
            listing_text(after)
        )),
        Outcome::SeveralGone(gone) => {
            let ports: Vec<String> = gone
                .iter()
                .map(|gone| gone.port.display().to_string())
                .collect();
            Some(format!(
                "{} ports disappeared ({}): unplug only the adapter of the arm. Reconnect the \
                 USB cables and run find-port again.",
                gone.len(),
                ports.join(", ")
            ))
        }
    }
}

/// The ports present now: every path matching a pattern (the `glob` crate's shell wildcards)
/// that resolves to something (a dangling link is a port that is gone), sorted, each once.
pub fn list_ports(globs: &[String]) -> Result<Vec<PortEntry>> {
    let mut ports = Vec::new();
    for pattern in globs {
        let paths = glob::glob(pattern)
            .with_context(|| format!("--dev-glob {pattern:?} is not a wildcard pattern"))?;
        // An entry that cannot be read (gone while listing) is no port.
        for path in paths.flatten() {
            if let Ok(device) = std::fs::canonicalize(&path) {
                ports.push(PortEntry { path, device });
            }
        }
    }
    ports.sort();
    ports.dedup();
    Ok(ports)
}

/// What the kernel says about the USB device behind a tty.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UsbIdentity {
    pub vendor: String,
    pub product: String,
    pub serial: Option<String>,
}

/// Reads vendor, product and serial number of the USB device above `tty_device_dir` (a sysfs
/// directory such as /sys/class/tty/ttyACM0/device, links resolved), walking up to the first
/// directory with idVendor.
pub fn usb_identity(tty_device_dir: &Path) -> Option<UsbIdentity> {
    let mut dir = std::fs::canonicalize(tty_device_dir).ok()?;
    loop {
        let read = |name: &str| {
            std::fs::read_to_string(dir.join(name))
                .ok()
                .map(|text| text.trim().to_owned())
        };
        if let Some(vendor) = read("idVendor") {
            return Some(UsbIdentity {
                vendor,
                product: read("idProduct").unwrap_or_default(),
                serial: read("serial").filter(|serial| !serial.is_empty()),
            });
        }
        if !dir.pop() || dir.as_os_str() == "/" {
            return None;
        }
    }
}

/// The USB identity of a device node such as /dev/ttyACM0 (None for a pty, or off Linux).
fn usb_identity_of(device: &Path) -> Option<UsbIdentity> {
    let name = device.file_name()?;
    usb_identity(&Path::new("/sys/class/tty").join(name).join("device"))
}

/// The `find-port` subcommand.
pub fn run(args: &FindPortArgs) -> Result<()> {
    let globs: Vec<String> = if args.dev_glob.is_empty() {
        DEFAULT_GLOBS
            .iter()
            .map(|glob| (*glob).to_owned())
            .collect()
    } else {
        args.dev_glob.clone()
    };
    println!("Finding all available ports of the servo bus adapter.");
    let before = list_ports(&globs)?;
    println!("Ports before disconnecting:\n{}", listing_text(&before));
    if before.is_empty() {
        bail!(
            "no serial port found ({}): is the adapter plugged in (and is it a USB serial \
             device)?",
            globs.join(", ")
        );
    }
    super::wait_for_enter("Remove the USB cable from the arm's adapter, then press Enter.")?;
    // The kernel removes the device a moment after the cable: look again for up to a second.
    let deadline = Instant::now() + SETTLE;
    let (after, outcome) = loop {
        let after = list_ports(&globs)?;
        let outcome = compare(&before, &after);
        if outcome != Outcome::NoneGone || Instant::now() >= deadline {
            break (after, outcome);
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    match &outcome {
        Outcome::Found(gone) => {
            println!(
                "{}",
                found_text(gone, usb_identity_of(&gone.device).as_ref())
            );
            Ok(())
        }
        _ => bail!(failure_text(&outcome, &after).unwrap_or_default()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(path: &str) -> PortEntry {
        PortEntry {
            path: path.into(),
            device: path.into(),
        }
    }

    fn link(path: &str, device: &str) -> PortEntry {
        PortEntry {
            path: path.into(),
            device: device.into(),
        }
    }

    #[test]
    fn the_one_port_that_disappeared_is_found() {
        let before = [node("/dev/ttyACM0"), node("/dev/ttyACM1")];
        let after = [node("/dev/ttyACM1")];
        let Outcome::Found(gone) = compare(&before, &after) else {
            panic!("not found");
        };
        assert_eq!(gone.port, PathBuf::from("/dev/ttyACM0"));
        assert!(gone.aliases.is_empty());
        let text = found_text(&gone, None);
        assert!(text.starts_with("The port of this adapter is /dev/ttyACM0"));
        assert!(text.ends_with("Reconnect the USB cable."));
    }

    #[test]
    fn names_of_one_device_count_as_one_adapter_named_by_its_node() {
        let by_id = "/dev/serial/by-id/usb-1a86_USB_Single_Serial_5A46082351-if00";
        let before = [
            link(by_id, "/dev/ttyACM0"),
            link("/dev/so101_follower", "/dev/ttyACM0"),
            node("/dev/ttyACM0"),
            node("/dev/ttyACM1"),
        ];
        let after = [node("/dev/ttyACM1")];
        let Outcome::Found(gone) = compare(&before, &after) else {
            panic!("not found");
        };
        assert_eq!(gone.port, PathBuf::from("/dev/ttyACM0"));
        assert_eq!(
            gone.aliases,
            [PathBuf::from(by_id), PathBuf::from("/dev/so101_follower")]
        );
        let usb = UsbIdentity {
            vendor: "1a86".into(),
            product: "55d3".into(),
            serial: Some("5A46082351".into()),
        };
        let text = found_text(&gone, Some(&usb));
        assert!(text.contains("also reachable as: /dev/serial/by-id/"));
        assert!(text.contains("1a86:55d3, serial number 5A46082351"));
    }

    #[test]
    fn a_link_alone_is_named_when_its_device_was_not_listed() {
        let before = [link("/tmp/x/bus", "/dev/pts/7"), node("/dev/ttyUSB0")];
        let after = [node("/dev/ttyUSB0")];
        assert_eq!(
            compare(&before, &after),
            Outcome::Found(Gone {
                device: "/dev/pts/7".into(),
                port: "/tmp/x/bus".into(),
                aliases: vec![],
            })
        );
    }

    #[test]
    fn nothing_gone_and_several_gone_are_failures_with_advice() {
        let before = [node("/dev/ttyACM0"), node("/dev/ttyUSB0")];
        let none = compare(&before, &before);
        assert_eq!(none, Outcome::NoneGone);
        let text = failure_text(&none, &before).unwrap();
        assert!(text.contains("No port disappeared"), "{text}");
        assert!(text.contains("/dev/ttyUSB0"), "{text}");
        assert!(text.contains("Reconnect the USB cable"), "{text}");

        let several = compare(&before, &[]);
        let Outcome::SeveralGone(gone) = &several else {
            panic!("{several:?}");
        };
        assert_eq!(gone.len(), 2);
        let text = failure_text(&several, &[]).unwrap();
        assert!(
            text.contains("2 ports disappeared (/dev/ttyACM0, /dev/ttyUSB0)"),
            "{text}"
        );
        assert!(text.contains("unplug only"), "{text}");
    }

    #[test]
    fn a_port_that_appeared_is_not_the_answer() {
        let before = [node("/dev/ttyACM0")];
        let after = [node("/dev/ttyACM0"), node("/dev/ttyACM1")];
        assert_eq!(compare(&before, &after), Outcome::NoneGone);
    }

    #[test]
    fn listing_shows_links_with_their_device() {
        let text = listing_text(&[node("/dev/ttyACM0"), link("/dev/a", "/dev/ttyACM0")]);
        assert_eq!(text, "  /dev/ttyACM0\n  /dev/a -> /dev/ttyACM0");
        assert_eq!(listing_text(&[]), "  (no serial ports)");
    }

    #[test]
    fn listing_follows_links_and_skips_dangling_ones() {
        let dir = tempfile::tempdir().unwrap();
        let device = dir.path().join("ttyFAKE0");
        std::fs::write(&device, "").unwrap();
        std::os::unix::fs::symlink(&device, dir.path().join("arm")).unwrap();
        std::os::unix::fs::symlink(dir.path().join("missing"), dir.path().join("gone")).unwrap();
        std::fs::write(dir.path().join("other"), "").unwrap();
        let globs = [
            format!("{}/ttyFAKE*", dir.path().display()),
            format!("{}/arm", dir.path().display()),
            format!("{}/gone", dir.path().display()),
            format!("{}/ttyFAKE0", dir.path().display()),
            "/nonexistent-dir/*".to_owned(),
        ];
        let ports = list_ports(&globs).unwrap();
        assert!(
            list_ports(&["/dev/[".to_owned()]).is_err(),
            "a broken pattern is reported"
        );
        let device = std::fs::canonicalize(&device).unwrap();
        assert_eq!(
            ports,
            [
                PortEntry {
                    path: dir.path().join("arm"),
                    device: device.clone()
                },
                PortEntry {
                    path: dir.path().join("ttyFAKE0"),
                    device
                },
            ]
        );
    }

    #[test]
    fn usb_identity_is_read_from_the_first_parent_with_ids() {
        let dir = tempfile::tempdir().unwrap();
        let usb = dir.path().join("usb1/1-2");
        let tty = usb.join("1-2:1.0/tty/ttyACM0");
        std::fs::create_dir_all(&tty).unwrap();
        std::fs::write(usb.join("idVendor"), "1a86\n").unwrap();
        std::fs::write(usb.join("idProduct"), "55d3\n").unwrap();
        std::fs::write(usb.join("serial"), "5A46082351\n").unwrap();
        assert_eq!(
            usb_identity(&tty),
            Some(UsbIdentity {
                vendor: "1a86".into(),
                product: "55d3".into(),
                serial: Some("5A46082351".into()),
            })
        );
        assert_eq!(usb_identity(&dir.path().join("nothing")), None);
    }
}
