//! The episode-bag layout that recorder_node writes and so101_viz and the Python converter read:
//! one directory per episode, `<prefix>_<index:06>/`, holding rosbag2's `metadata.yaml` and the
//! MCAP file(s) `<dir name>_<split>.mcap`; the episode's facts in rosbag2's `custom_data`. The
//! Python reader follows the same rules (python/src/so101/dataset/bags.py) and is tested against the same
//! cases (tests/fixtures/episode_bags.txt).

use std::path::{Path, PathBuf};

/// rosbag2's metadata file, written when an episode is closed.
pub const METADATA_FILE: &str = "metadata.yaml";
/// The recorder's default directory prefix.
pub const DEFAULT_PREFIX: &str = "episode";

/// Keys of the episode's `custom_data` in metadata.yaml (and of the MCAP `episode` record).
pub mod custom_data {
    pub const EPISODE_INDEX: &str = "episode_index";
    pub const TASK: &str = "task";
    /// "true", "false" or "unknown".
    pub const SUCCESS: &str = "success";
    /// The sim's episode seed, empty when unknown.
    pub const SEED: &str = "seed";
    /// JSON of what the sim simulated the episode with (/sim/episode: servo model, randomization
    /// ranges and draw); empty on the real arm.
    pub const SIMULATION: &str = "simulation";
}

/// The directory name of episode `index`.
pub fn episode_dir_name(prefix: &str, index: u64) -> String {
    format!("{prefix}_{index:06}")
}

/// The name of the `split`-th MCAP file of the episode directory `dir_name`.
pub fn mcap_file_name(dir_name: &str, split: usize) -> String {
    format!("{dir_name}_{split}.mcap")
}

#[derive(Debug, thiserror::Error)]
pub enum LayoutError {
    #[error("{0}: neither an episode directory nor a directory of episodes")]
    NotFound(PathBuf),
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// The MCAP files in `dir`, in split order (`_0`, `_1`, ..., `_10`; names without a split
/// number after those, by name).
pub fn mcap_files(dir: &Path) -> Result<Vec<PathBuf>, LayoutError> {
    let entries = std::fs::read_dir(dir).map_err(|source| LayoutError::Read {
        path: dir.to_owned(),
        source,
    })?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|path| path.is_file() && path.extension().is_some_and(|ext| ext == "mcap"))
        .collect();
    files.sort_by_key(|path| (split_number(path).unwrap_or(u64::MAX), path.clone()));
    Ok(files)
}

fn split_number(path: &Path) -> Option<u64> {
    let stem = path.file_stem()?.to_str()?;
    stem.rsplit_once('_')?.1.parse().ok()
}

/// Does the directory's name end in `_<index>` (six or more digits), as the recorder names them?
fn has_episode_name(dir: &Path) -> bool {
    dir.file_name()
        .and_then(|name| name.to_str())
        .and_then(|name| name.rsplit_once('_'))
        .is_some_and(|(prefix, index)| {
            !prefix.is_empty() && index.len() >= 6 && index.bytes().all(|b| b.is_ascii_digit())
        })
}

/// Is `dir` an episode: a metadata.yaml or an MCAP file in it (an episode cut short has no
/// metadata.yaml; the reader reports it)?
pub fn is_episode_dir(dir: &Path) -> bool {
    dir.join(METADATA_FILE).is_file() || mcap_files(dir).is_ok_and(|files| !files.is_empty())
}

/// The episodes the user means by `paths`: each path that is an episode itself, and the episode
/// directories named `<prefix>_<index>` inside each of the others, in name order; in the order
/// the paths were given. A path that does not exist is an error.
pub fn episode_dirs(paths: &[PathBuf]) -> Result<Vec<PathBuf>, LayoutError> {
    let mut found = Vec::new();
    for path in paths {
        if is_episode_dir(path) {
            found.push(path.clone());
            continue;
        }
        if !path.is_dir() {
            return Err(LayoutError::NotFound(path.clone()));
        }
        let entries = std::fs::read_dir(path).map_err(|source| LayoutError::Read {
            path: path.clone(),
            source,
        })?;
        let mut inner: Vec<PathBuf> = entries
            .filter_map(|entry| entry.ok().map(|e| e.path()))
            .filter(|child| child.is_dir() && has_episode_name(child) && is_episode_dir(child))
            .collect();
        inner.sort();
        found.extend(inner);
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_recorder() {
        assert_eq!(episode_dir_name(DEFAULT_PREFIX, 5), "episode_000005");
        assert_eq!(mcap_file_name("episode_000005", 2), "episode_000005_2.mcap");
    }

    struct Case {
        name: String,
        tree: Vec<String>,
        given: Vec<String>,
        episodes: Option<Vec<String>>,
        mcap: Option<Vec<String>>,
    }

    fn cases() -> Vec<Case> {
        let text = include_str!("../../../tests/fixtures/episode_bags.txt");
        let mut cases: Vec<Case> = Vec::new();
        for line in text
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        {
            let (key, value) = line.split_once(':').expect("key: value");
            let words: Vec<String> = value.split_whitespace().map(str::to_owned).collect();
            match key {
                "case" => cases.push(Case {
                    name: value.trim().to_owned(),
                    tree: vec![],
                    given: vec![],
                    episodes: None,
                    mcap: None,
                }),
                "tree" => cases.last_mut().unwrap().tree = words,
                "given" => cases.last_mut().unwrap().given = words,
                "episodes" => {
                    cases.last_mut().unwrap().episodes = (words != ["error"]).then_some(words)
                }
                "mcap" => cases.last_mut().unwrap().mcap = Some(words),
                other => panic!("unknown key {other}"),
            }
        }
        cases
    }

    #[test]
    fn the_shared_cases_hold() {
        let cases = cases();
        assert!(cases.len() >= 5);
        for case in cases {
            let root = tempfile::tempdir().unwrap();
            for entry in &case.tree {
                let path = root.path().join(entry);
                if entry.ends_with('/') {
                    std::fs::create_dir_all(&path).unwrap();
                } else {
                    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
                    std::fs::write(&path, b"").unwrap();
                }
            }
            let given: Vec<PathBuf> = case.given.iter().map(|g| root.path().join(g)).collect();
            let found = episode_dirs(&given);
            match &case.episodes {
                None => assert!(found.is_err(), "{}: {found:?}", case.name),
                Some(expected) => {
                    let found = found.unwrap();
                    let relative: Vec<String> = found
                        .iter()
                        .map(|p| {
                            p.strip_prefix(root.path())
                                .unwrap()
                                .to_string_lossy()
                                .into_owned()
                        })
                        .collect();
                    assert_eq!(&relative, expected, "{}", case.name);
                    if let Some(order) = &case.mcap {
                        let files: Vec<String> = mcap_files(&found[0])
                            .unwrap()
                            .iter()
                            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
                            .collect();
                        assert_eq!(&files, order, "{}", case.name);
                    }
                }
            }
        }
    }
}
