//! The scene's shapes as its MJCF file draws them. Per arm link: the boxes MuJoCo collides with
//! (always there) and the visual meshes (when the fetched mesh files are present), posed in the
//! link's own frame, the frame `so101_core::kinematics` moves. The fixed furniture (table, bin),
//! posed in the world, and the cube's size.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use so101_core::kinematics::{BASE_LINK, LINK_NAMES};

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("cannot read the scene {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("the scene {path} is no valid XML: {source}")]
    Parse {
        path: PathBuf,
        source: roxmltree::Error,
    },
    #[error("the scene has no body {0:?}")]
    MissingBody(String),
    #[error("bad attribute {attribute}={value:?} on a geom of body {body}")]
    Attribute {
        body: String,
        attribute: &'static str,
        value: String,
    },
}

/// A box: pose of its centre in the link frame and half extents (m), as MuJoCo's `size`.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxShape {
    pub pose: Isometry3<f64>,
    pub half_extents: [f64; 3],
}

/// A mesh file placed in the link frame (units: m).
#[derive(Debug, Clone, PartialEq)]
pub struct MeshShape {
    pub pose: Isometry3<f64>,
    pub file: PathBuf,
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct LinkGeometry {
    pub boxes: Vec<BoxShape>,
    pub meshes: Vec<MeshShape>,
}

/// Bodies of the scene that never move, drawn around the arm.
pub const FURNITURE: [&str; 2] = ["table", "bin"];

/// A fixed body: its pose in the world and its boxes (in its own frame).
#[derive(Debug, Clone, PartialEq)]
pub struct FixedBody {
    pub pose: Isometry3<f64>,
    pub geometry: LinkGeometry,
}

/// The geometry of the base and the six moving links by link name, the furniture, the cube.
#[derive(Debug, Clone)]
pub struct SceneGeometry {
    /// Where the scene mounts the arm's base in its world.
    pub base_pose: Isometry3<f64>,
    pub links: BTreeMap<String, LinkGeometry>,
    pub furniture: BTreeMap<String, FixedBody>,
    /// The cube's half extents (m), when the scene has one.
    pub cube_half_extents: Option<[f64; 3]>,
}

impl SceneGeometry {
    /// Reads the arm's geometry from the MJCF scene at `path`; mesh files are resolved against the
    /// scene's `meshdir` and kept only when they exist.
    pub fn from_scene_file(path: &Path) -> Result<Self, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Read {
            path: path.to_owned(),
            source,
        })?;
        let directory = path.parent().unwrap_or(Path::new("."));
        Self::from_scene(&text, directory).map_err(|error| match error {
            SceneError::Parse { source, .. } => SceneError::Parse {
                path: path.to_owned(),
                source,
            },
            other => other,
        })
    }

    /// As [`Self::from_scene_file`], from the scene's text and the directory it lives in.
    pub fn from_scene(text: &str, directory: &Path) -> Result<Self, SceneError> {
        let document = roxmltree::Document::parse(text).map_err(|source| SceneError::Parse {
            path: PathBuf::new(),
            source,
        })?;
        let root = document.root_element();
        let mesh_dir = root
            .descendants()
            .find(|node| node.has_tag_name("compiler"))
            .and_then(|node| node.attribute("meshdir"))
            .map_or_else(|| directory.to_owned(), |dir| directory.join(dir));
        let mesh_files: BTreeMap<&str, PathBuf> = root
            .descendants()
            .filter(|node| {
                node.has_tag_name("mesh")
                    && node
                        .parent_element()
                        .is_some_and(|p| p.has_tag_name("asset"))
            })
            .filter_map(|node| {
                Some((
                    node.attribute("name")?,
                    mesh_dir.join(node.attribute("file")?),
                ))
            })
            .collect();

        // The geom type each default class sets.
        let class_types: BTreeMap<&str, &str> = root
            .descendants()
            .filter(|node| node.has_tag_name("default"))
            .filter_map(|default| {
                let class = default.attribute("class")?;
                let geom = default.children().find(|node| node.has_tag_name("geom"))?;
                Some((class, geom.attribute("type")?))
            })
            .collect();
        let body_named = |name: &str| {
            root.descendants()
                .find(|node| node.has_tag_name("body") && node.attribute("name") == Some(name))
        };
        let mut links = BTreeMap::new();
        for name in std::iter::once(BASE_LINK).chain(LINK_NAMES) {
            let body = body_named(name).ok_or_else(|| SceneError::MissingBody(name.to_owned()))?;
            let mut geometry = LinkGeometry::default();
            for geom in body.children().filter(|node| node.has_tag_name("geom")) {
                let pose = geom_pose(name, &geom)?;
                match (geom_type(&geom, &class_types), geom.attribute("mesh")) {
                    ("mesh", Some(mesh)) => {
                        if let Some(file) = mesh_files.get(mesh).filter(|file| file.is_file()) {
                            geometry.meshes.push(MeshShape {
                                pose,
                                file: file.clone(),
                            });
                        }
                    }
                    // The collision boxes and finger pads.
                    ("box", _) => {
                        let size = numbers::<3>(name, &geom, "size")?.ok_or_else(|| {
                            SceneError::Attribute {
                                body: name.to_owned(),
                                attribute: "size",
                                value: String::new(),
                            }
                        })?;
                        geometry.boxes.push(BoxShape {
                            pose,
                            half_extents: size,
                        });
                    }
                    _ => {}
                }
            }
            links.insert(name.to_owned(), geometry);
        }
        let mut furniture = BTreeMap::new();
        for name in FURNITURE {
            let Some(body) = body_named(name) else {
                continue;
            };
            let mut geometry = LinkGeometry::default();
            for geom in body
                .children()
                .filter(|node| node.has_tag_name("geom") && node.attribute("type") == Some("box"))
            {
                if let Some(size) = numbers::<3>(name, &geom, "size")? {
                    geometry.boxes.push(BoxShape {
                        pose: geom_pose(name, &geom)?,
                        half_extents: size,
                    });
                }
            }
            furniture.insert(
                name.to_owned(),
                FixedBody {
                    pose: geom_pose(name, &body)?,
                    geometry,
                },
            );
        }
        let cube_half_extents = match body_named("cube")
            .and_then(|body| body.children().find(|node| node.has_tag_name("geom")))
        {
            Some(geom) => numbers::<3>("cube", &geom, "size")?,
            None => None,
        };
        let base =
            body_named(BASE_LINK).ok_or_else(|| SceneError::MissingBody(BASE_LINK.to_owned()))?;
        Ok(Self {
            base_pose: geom_pose(BASE_LINK, &base)?,
            links,
            furniture,
            cube_half_extents,
        })
    }

    /// Whether every link has its meshes (the fetched meshes are installed).
    pub fn has_meshes(&self) -> bool {
        self.links.values().all(|link| !link.meshes.is_empty())
    }
}

/// A geom's type: its own, else its class default's, else MuJoCo's default (sphere).
fn geom_type<'a>(geom: &roxmltree::Node<'a, '_>, class_types: &BTreeMap<&str, &'a str>) -> &'a str {
    geom.attribute("type")
        .or_else(|| {
            geom.attribute("class")
                .and_then(|class| class_types.get(class).copied())
        })
        .unwrap_or("sphere")
}

fn geom_pose(body: &str, geom: &roxmltree::Node) -> Result<Isometry3<f64>, SceneError> {
    let position = numbers::<3>(body, geom, "pos")?.unwrap_or([0.0; 3]);
    let [w, x, y, z] = numbers::<4>(body, geom, "quat")?.unwrap_or([1.0, 0.0, 0.0, 0.0]);
    Ok(Isometry3::from_parts(
        Translation3::from(Vector3::from(position)),
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
    ))
}

/// `N` numbers of an attribute, None when the attribute is absent.
fn numbers<const N: usize>(
    body: &str,
    node: &roxmltree::Node,
    attribute: &'static str,
) -> Result<Option<[f64; N]>, SceneError> {
    let Some(text) = node.attribute(attribute) else {
        return Ok(None);
    };
    let bad = || SceneError::Attribute {
        body: body.to_owned(),
        attribute,
        value: text.to_owned(),
    };
    let values: Vec<f64> = text
        .split_whitespace()
        .map(str::parse)
        .collect::<Result<_, _>>()
        .map_err(|_| bad())?;
    values.try_into().map(Some).map_err(|_| bad())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene() -> SceneGeometry {
        SceneGeometry::from_scene_file(Path::new(so101_core::robot::DEFAULT_SCENE))
            .expect("the project's scene parses")
    }

    #[test]
    fn every_link_of_the_scene_has_its_collision_boxes() {
        let geometry = scene();
        assert_eq!(geometry.links.len(), 7);
        for (name, link) in &geometry.links {
            assert!(!link.boxes.is_empty(), "{name} has no box");
            for shape in &link.boxes {
                assert!(
                    shape.half_extents.iter().all(|h| *h > 0.0 && *h < 0.1),
                    "{name}: {shape:?}"
                );
            }
        }
        // The gripper carries its palm, the fixed finger and its pad.
        assert_eq!(geometry.links["gripper"].boxes.len(), 3);
        // The table's top and legs, the bin's floor and walls, in the world; the 3 cm cube.
        assert_eq!(geometry.furniture["table"].geometry.boxes.len(), 5);
        assert_eq!(geometry.furniture["bin"].geometry.boxes.len(), 5);
        assert!((geometry.furniture["bin"].pose.translation.vector.z - 0.75).abs() < 1e-12);
        assert_eq!(geometry.cube_half_extents, Some([0.015; 3]));
        assert!((geometry.base_pose.translation.vector.z - 0.75).abs() < 1e-12);
    }

    #[test]
    fn meshes_are_taken_only_where_their_files_exist() {
        let text = r#"<mujoco><compiler meshdir="nowhere"/><default><default class="pad"><geom type="box"/></default></default><asset><mesh name="m" file="m.stl"/></asset>
            <worldbody><body name="base"><geom class="mesh_visual" mesh="m"/>
            <geom class="link_collision" type="box" size="0.01 0.02 0.03" pos="0 0 0.1"/>
            <geom class="link_collision" size="0.01"/><geom class="pad" size="0.1 0.1 0.1"/>
            <body name="shoulder"><geom class="link_collision" type="box" size="1 1 1"/>
            <body name="upper_arm"><body name="lower_arm"><body name="wrist"><body name="gripper">
            <body name="moving_jaw"/></body></body></body></body></body></body></worldbody></mujoco>"#;
        let geometry = SceneGeometry::from_scene(text, Path::new("/")).expect("parses");
        assert!(geometry.links["base"].meshes.is_empty());
        assert_eq!(
            geometry.links["base"].boxes[0].half_extents,
            [0.01, 0.02, 0.03]
        );
        assert!((geometry.links["base"].boxes[0].pose.translation.vector.z - 0.1).abs() < 1e-12);
        assert!(!geometry.has_meshes());
    }

    #[test]
    fn a_malformed_attribute_is_an_error_naming_the_body() {
        let text = r#"<mujoco><worldbody><body name="base"><geom class="link_collision" type="box" size="1 x 1"/></body></worldbody></mujoco>"#;
        let error = SceneGeometry::from_scene(text, Path::new("/")).expect_err("bad size");
        assert!(error.to_string().contains("base"), "{error}");
    }
}
