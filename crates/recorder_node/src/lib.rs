//! recorder_node: rosbag2-compatible MCAP recording of the stack's topics, episode by episode.
//!
//! Pure logic: `topics` (selection, names, schemas), `episodes` (events, episode metadata),
//! `metadata` (rosbag2's YAML), `gaps` (loss detection). I/O: `raw` (wire bytes from DDS), `bag`
//! (MCAP files), `node` (subscriptions, control, the writer thread).

pub mod bag;
pub mod cli;
pub mod episodes;
pub mod gaps;
pub mod metadata;
pub mod node;
pub mod parameters;
pub mod raw;
pub mod topics;
