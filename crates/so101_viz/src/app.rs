//! so101_rerun: the stack in the Rerun viewer, live or from episode bags.

use std::path::Path;

use anyhow::{bail, Context as _, Result};
use nalgebra::Isometry3;
use so101_core::ros::shutdown::Shutdown;

use crate::bag;
use crate::bridge::Bridge;
use crate::cli::{BagArgs, Command, LiveArgs, RerunArgs, SceneArgs};
use crate::rerun_log::SceneLog;
use crate::scene_geometry::SceneGeometry;

const APPLICATION_ID: &str = "so101";

fn scene_log(rec: rerun::RecordingStream, args: &SceneArgs) -> Result<SceneLog> {
    let scene = SceneGeometry::from_scene_file(&args.scene)?;
    let meshes = !args.no_meshes && scene.has_meshes();
    let base = args
        .base_xyz
        .map_or(scene.base_pose, |[x, y, z]| Isometry3::translation(x, y, z));
    let log = SceneLog::new(rec);
    log.scene(&scene, &base, meshes)?;
    Ok(log)
}

pub fn run(args: RerunArgs) -> Result<()> {
    match &args.command {
        Command::Live(live) => run_live(live, &args.scene),
        Command::Bag(bags) => run_bags(bags, &args.scene),
    }
}

fn run_live(args: &LiveArgs, scene: &SceneArgs) -> Result<()> {
    let builder = rerun::RecordingStreamBuilder::new(APPLICATION_ID);
    let rec = if let Some(path) = &args.save {
        builder
            .save(path)
            .with_context(|| format!("cannot write {}", path.display()))?
    } else if let Some(url) = &args.connect {
        builder
            .connect_grpc_opts(url.clone())
            .with_context(|| format!("cannot connect to {url}"))?
    } else if args.spawn {
        builder
            .spawn()
            .context("cannot start the viewer (is `rerun` on PATH? .venv/bin has one)")?
    } else {
        bail!("where to: --save FILE.rrd, --connect [URL] or --spawn");
    };
    let shutdown = Shutdown::on_signals().context("cannot install the signal handlers")?;
    let cameras: Vec<String> = args
        .cameras
        .iter()
        .filter(|c| !c.is_empty() && *c != "none")
        .cloned()
        .collect();
    let mut bridge = Bridge::new(scene_log(rec, scene)?, scene.image_rate);
    let parameters = crate::parameters::bridge(args, scene);
    crate::live::run(
        &mut bridge,
        &args.node,
        parameters,
        &cameras,
        args.duration,
        &shutdown,
    )?;
    bridge
        .log()
        .stream()
        .flush_blocking()
        .context("cannot flush the recording")?;
    tracing::info!(counts = ?bridge.counts, "bridge stopped");
    Ok(())
}

fn run_bags(args: &BagArgs, scene: &SceneArgs) -> Result<()> {
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("cannot create {}", args.output.display()))?;
    let episodes = so101_core::episode_bag::episode_dirs(&args.bags)?;
    if episodes.is_empty() {
        bail!("no episode bags in {:?}", args.bags);
    }
    let (mut written, mut failed) = (0, 0);
    let mut used = std::collections::BTreeSet::new();
    for (index, episode) in episodes.iter().enumerate() {
        let name = recording_name(episode, &mut used);
        let output = args.output.join(format!("{name}.rrd"));
        match convert_one(episode, &output, &name, scene) {
            Ok(report) => {
                written += 1;
                if let Some(reason) = &report.truncated {
                    tracing::warn!(episode = %name, %reason, "bag ends early: what was read is kept");
                }
                tracing::info!(
                    "[{}/{}] {} -> {} ({} messages, {} undecodable)",
                    index + 1,
                    episodes.len(),
                    episode.display(),
                    output.display(),
                    report.messages,
                    report.undecodable
                );
            }
            Err(error) => {
                failed += 1;
                tracing::error!(episode = %episode.display(), "skipped: {error:#}");
            }
        }
    }
    println!(
        "{written} recording(s) in {}; {failed} episode(s) skipped",
        args.output.display()
    );
    if written == 0 {
        bail!("no episode could be converted");
    }
    Ok(())
}

/// The recording's name (and file name): the episode directory's, prefixed with its parent's
/// where two episodes of one run share a name (episode_000000 of two sessions), numbered if
/// still taken, so no recording overwrites another.
fn recording_name(episode: &Path, used: &mut std::collections::BTreeSet<String>) -> String {
    let base = episode.file_name().map_or_else(
        || so101_core::episode_bag::DEFAULT_PREFIX.into(),
        |n| n.to_string_lossy().into_owned(),
    );
    let parent = episode
        .parent()
        .and_then(Path::file_name)
        .map(|n| n.to_string_lossy().into_owned());
    let mut candidates = std::iter::once(base.clone())
        .chain(parent.map(|parent| format!("{parent}_{base}")))
        .chain((2..).map(|k| format!("{base}_{k}")));
    let name = candidates
        .find(|candidate| !used.contains(candidate))
        .unwrap_or(base);
    used.insert(name.clone());
    name
}

fn convert_one(
    episode: &Path,
    output: &Path,
    name: &str,
    scene: &SceneArgs,
) -> Result<bag::BagReport> {
    // Checked before the file is created, so a bad bag leaves no empty recording behind.
    bag::mcap_files(episode)?;
    let rec = rerun::RecordingStreamBuilder::new(APPLICATION_ID)
        .recording_id(name)
        .save(output)
        .with_context(|| format!("cannot write {}", output.display()))?;
    let mut bridge = Bridge::new(scene_log(rec, scene)?, scene.image_rate);
    let report = bag::replay(episode, &mut bridge)?;
    bridge
        .log()
        .stream()
        .flush_blocking()
        .context("cannot flush the recording")?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn episodes_of_the_same_name_get_recordings_of_their_own() {
        let mut used = std::collections::BTreeSet::new();
        let names: Vec<String> = [
            "a/bags/episode_000000",
            "b/bags/episode_000000",
            "b/bags/episode_000000",
            "c/episode_000001",
        ]
        .iter()
        .map(|path| recording_name(Path::new(path), &mut used))
        .collect();
        assert_eq!(
            names,
            [
                "episode_000000",
                "bags_episode_000000",
                "episode_000000_2",
                "episode_000001"
            ]
        );
    }
}
