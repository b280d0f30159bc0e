//! The robot description (URDF) of the arm: joints and limits from the shared kinematic model,
//! shapes from the scene file (meshes when present, else its collision boxes), so RViz draws the
//! same arm the sim moves.

use std::fmt::Write as _;

use nalgebra::Isometry3;
use so101_core::kinematics::{joint_origin, BASE_LINK, GRASP_POINT, LINK_NAMES, PARENT_LINKS};
use so101_core::robot::{JOINT_LIMITS, JOINT_NAMES};

use crate::scene_geometry::{BoxShape, SceneGeometry};

/// The frame of the grasp point (a fixed child of the gripper), for tools that want the tool tip.
pub const GRASP_LINK: &str = "grasp_point";

/// The ROS package whose share directory holds the meshes (`so101-description install` makes it).
pub const DESCRIPTION_PACKAGE: &str = "so101_description";

/// How the URDF names its mesh files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MeshUri {
    /// `package://so101_description/meshes/FILE`: resolves on any machine where the package is
    /// installed (RViz and MoveIt look it up in AMENT_PREFIX_PATH).
    Package,
    /// `file:///absolute/path`: only on this machine, no package needed.
    File,
}

/// The URI of `file` in the URDF.
pub fn mesh_uri(file: &std::path::Path, kind: MeshUri) -> String {
    match kind {
        MeshUri::Package => format!(
            "package://{DESCRIPTION_PACKAGE}/meshes/{}",
            file.file_name().unwrap_or_default().to_string_lossy()
        ),
        MeshUri::File => format!(
            "file://{}",
            file.canonicalize().unwrap_or(file.to_path_buf()).display()
        ),
    }
}

/// The URDF text. With `meshes` the links are drawn with the scene's mesh files, named as `uris`
/// says; the boxes are always the collision shapes.
pub fn robot_description(geometry: &SceneGeometry, meshes: Option<MeshUri>) -> String {
    let mut out = String::from("<?xml version=\"1.0\"?>\n<robot name=\"so101\">\n");
    out.push_str("  <material name=\"printed\"><color rgba=\"0.93 0.93 0.9 1\"/></material>\n");
    out.push_str("  <material name=\"box\"><color rgba=\"0.95 0.55 0.15 1\"/></material>\n");
    for name in std::iter::once(BASE_LINK).chain(LINK_NAMES) {
        let _ = writeln!(out, "  <link name=\"{name}\">");
        if let Some(link) = geometry.links.get(name) {
            if let Some(kind) = meshes.filter(|_| !link.meshes.is_empty()) {
                for mesh in &link.meshes {
                    let uri = mesh_uri(&mesh.file, kind);
                    let _ = writeln!(
                        out,
                        "    <visual>{}<geometry><mesh filename=\"{}\"/></geometry><material name=\"printed\"/></visual>",
                        origin(&mesh.pose),
                        escape(&uri)
                    );
                }
            } else {
                for shape in &link.boxes {
                    out.push_str(&box_element("visual", shape, "<material name=\"box\"/>"));
                }
            }
            for shape in &link.boxes {
                out.push_str(&box_element("collision", shape, ""));
            }
        }
        out.push_str("  </link>\n");
    }
    for (index, name) in JOINT_NAMES.iter().enumerate() {
        let limit = JOINT_LIMITS[index];
        let _ = writeln!(
            out,
            "  <joint name=\"{name}\" type=\"revolute\">\n    <parent link=\"{}\"/>\n    <child link=\"{}\"/>\n    {}\n    <axis xyz=\"0 0 1\"/>\n    <limit lower=\"{}\" upper=\"{}\" effort=\"3\" velocity=\"6\"/>\n  </joint>",
            PARENT_LINKS[index],
            LINK_NAMES[index],
            origin(&joint_origin(index)),
            limit.min,
            limit.max
        );
    }
    let [x, y, z] = GRASP_POINT;
    let _ = writeln!(
        out,
        "  <link name=\"{GRASP_LINK}\"/>\n  <joint name=\"grasp_point_joint\" type=\"fixed\">\n    <parent link=\"gripper\"/>\n    <child link=\"{GRASP_LINK}\"/>\n    <origin xyz=\"{x} {y} {z}\" rpy=\"0 0 0\"/>\n  </joint>"
    );
    out.push_str("</robot>\n");
    out
}

/// `<origin xyz rpy>`: URDF's roll-pitch-yaw are fixed-axis X, Y, Z turns (R = Rz Ry Rx), what
/// nalgebra's euler_angles gives.
fn origin(pose: &Isometry3<f64>) -> String {
    let t = pose.translation.vector;
    let (roll, pitch, yaw) = pose.rotation.euler_angles();
    format!(
        "<origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>",
        t.x, t.y, t.z, roll, pitch, yaw
    )
}

/// A `<visual>` or `<collision>` line drawing `shape`, with `extra` (a material) inside.
fn box_element(tag: &str, shape: &BoxShape, extra: &str) -> String {
    let [x, y, z] = shape.half_extents;
    format!(
        "    <{tag}>{}<geometry><box size=\"{} {} {}\"/></geometry>{extra}</{tag}>\n",
        origin(&shape.pose),
        2.0 * x,
        2.0 * y,
        2.0 * z
    )
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('"', "&quot;")
        .replace('<', "&lt;")
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion};

    use super::*;
    use crate::scene_geometry::SceneGeometry;

    fn description(meshes: Option<MeshUri>) -> String {
        let geometry =
            SceneGeometry::from_scene_file(std::path::Path::new(so101_core::robot::DEFAULT_SCENE))
                .expect("the project's scene parses");
        robot_description(&geometry, meshes)
    }

    fn isometry_of(origin: roxmltree::Node) -> Isometry3<f64> {
        let parse = |name: &str| -> Vec<f64> {
            origin
                .attribute(name)
                .expect("attribute")
                .split_whitespace()
                .map(|v| v.parse().expect("number"))
                .collect()
        };
        let (xyz, rpy) = (parse("xyz"), parse("rpy"));
        Isometry3::from_parts(
            Translation3::new(xyz[0], xyz[1], xyz[2]),
            UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
        )
    }

    #[test]
    fn the_joints_reproduce_the_kinematic_model() {
        let text = description(None);
        let document = roxmltree::Document::parse(&text).expect("valid XML");
        let joints: Vec<_> = document
            .descendants()
            .filter(|n| n.has_tag_name("joint"))
            .collect();
        assert_eq!(joints.len(), 7);
        for (index, name) in JOINT_NAMES.iter().enumerate() {
            let joint = joints
                .iter()
                .find(|j| j.attribute("name") == Some(name))
                .expect("joint");
            let child = |tag: &str| joint.children().find(|n| n.has_tag_name(tag)).expect(tag);
            assert_eq!(child("parent").attribute("link"), Some(PARENT_LINKS[index]));
            assert_eq!(child("child").attribute("link"), Some(LINK_NAMES[index]));
            let parsed = isometry_of(child("origin"));
            let model = joint_origin(index);
            assert!(
                (parsed.translation.vector - model.translation.vector).norm() < 1e-12,
                "{name}"
            );
            assert!(
                parsed.rotation.angle_to(&model.rotation) < 1e-9,
                "{name}: rpy does not give the model's rotation"
            );
            let limit = child("limit");
            assert_eq!(
                limit
                    .attribute("lower")
                    .map(|v| v.parse::<f64>().expect("number")),
                Some(JOINT_LIMITS[index].min)
            );
        }
        // Every link joined once: a tree.
        let links = document
            .descendants()
            .filter(|n| n.has_tag_name("link"))
            .count();
        assert_eq!(links, 8);
    }

    #[test]
    fn without_meshes_the_links_are_drawn_with_their_boxes() {
        let text = description(None);
        assert!(!text.contains("<mesh"));
        assert!(text.matches("<visual>").count() >= 7);
    }

    #[test]
    fn mesh_uris_are_package_relative_or_absolute_files() {
        let file = std::path::Path::new("/somewhere/meshes/base_so101_v2.stl");
        assert_eq!(
            mesh_uri(file, MeshUri::Package),
            "package://so101_description/meshes/base_so101_v2.stl"
        );
        assert_eq!(
            mesh_uri(file, MeshUri::File),
            "file:///somewhere/meshes/base_so101_v2.stl"
        );
    }
}
