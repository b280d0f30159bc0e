//! The scene variants: the full scene with the visual meshes fetched at set-up, and the mesh-free
//! "lite" variant derived from it, so both share one kinematic and collision description.
//! The transform is pure; `load` reads the file and compiles the chosen variant.

use std::path::Path;

use anyhow::Context;
use quick_xml::{
    events::{BytesStart, Event},
    Reader, Writer,
};

use crate::mujoco::{ObjectKind, Simulation};

/// Height of the table's top in the world (m): the table_top geom's upper face.
pub const TABLE_TOP_Z: f64 = 0.75;

/// Bodies whose geoms are the workspace a real background replaces: the world's own (the floor)
/// and the table. The arm, the cube and the bin stay in front of it.
pub const BACKGROUND_BODIES: [&str; 2] = ["world", "table"];

/// By geom id: whether the geom belongs to [`BACKGROUND_BODIES`].
pub fn background_geoms(sim: &Simulation) -> Vec<bool> {
    let bodies: Vec<usize> = BACKGROUND_BODIES
        .iter()
        .filter_map(|name| sim.id(ObjectKind::Body, name))
        .collect();
    (0..sim.geom_count())
        .map(|geom| bodies.contains(&sim.geom_body(geom)))
        .collect()
}

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("scene XML is malformed: {0}")]
    Xml(String),
}

/// Loads the scene at `path`, in its lite variant when `lite` is set.
pub fn load(path: &Path, lite: bool) -> anyhow::Result<Simulation> {
    if !lite {
        return Simulation::from_xml_file(path).with_context(|| {
            format!(
                "{} (the visual meshes come from scripts/setup.sh; --lite runs without them)",
                path.display()
            )
        });
    }
    let xml = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the scene {}", path.display()))?;
    let lite_xml = lite_variant(&xml).with_context(|| format!("scene {}", path.display()))?;
    {
        // Named beside the original, so what else the scene refers to is found as without --lite.
        let name = path.with_file_name("so101_scene_lite.xml");
        Simulation::from_xml_text(&lite_xml, &name.to_string_lossy())
    }
    .with_context(|| format!("lite variant of {}", path.display()))
}

/// The lite variant of an MJCF scene: every `<mesh>` asset and every geom that uses a mesh is
/// removed, so the scene loads without the third-party mesh files and renders only primitives.
pub fn lite_variant(xml: &str) -> Result<String, SceneError> {
    let mut reader = Reader::from_str(xml);
    let mut writer = Writer::new(Vec::with_capacity(xml.len()));
    let mut skip_depth = 0usize;
    loop {
        let event = reader
            .read_event()
            .map_err(|error| SceneError::Xml(error.to_string()))?;
        match event {
            Event::Eof => break,
            Event::Start(ref element) if skip_depth > 0 || uses_mesh(element)? => skip_depth += 1,
            Event::End(_) if skip_depth > 0 => skip_depth -= 1,
            Event::Empty(ref element) if skip_depth > 0 || uses_mesh(element)? => {}
            _ if skip_depth > 0 => {}
            event => writer
                .write_event(event)
                .map_err(|error| SceneError::Xml(error.to_string()))?,
        }
    }
    String::from_utf8(writer.into_inner()).map_err(|error| SceneError::Xml(error.to_string()))
}

/// A mesh asset, or a geom whose shape is a mesh.
fn uses_mesh(element: &BytesStart) -> Result<bool, SceneError> {
    match element.name().as_ref() {
        b"mesh" => Ok(true),
        b"geom" => {
            for attribute in element.attributes() {
                let attribute = attribute.map_err(|error| SceneError::Xml(error.to_string()))?;
                if attribute.key.as_ref() == b"mesh" {
                    return Ok(true);
                }
            }
            Ok(false)
        }
        _ => Ok(false),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn removes_mesh_assets_and_mesh_geoms_only() {
        let xml = r#"<mujoco><asset><mesh name="base" file="base.stl"/><material name="m"/></asset>
<worldbody><body name="b"><geom type="mesh" mesh="base"/><geom type="box" size="1 1 1"/>
<geom mesh="x"></geom><site name="s"/></body></worldbody></mujoco>"#;
        let lite = lite_variant(xml).unwrap();
        assert!(!lite.contains("mesh"), "{lite}");
        assert!(lite.contains(r#"<material name="m"/>"#));
        assert!(lite.contains(r#"<geom type="box" size="1 1 1"/>"#));
        assert!(lite.contains(r#"<site name="s"/>"#));
        assert!(lite.contains("</body></worldbody></mujoco>"));
    }

    #[test]
    fn malformed_xml_is_an_error() {
        assert!(lite_variant("<mujoco><geom mesh=></mujoco>").is_err());
    }
}
