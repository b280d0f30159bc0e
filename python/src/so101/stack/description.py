"""so101-description: the arm's description as a ROS package, so RViz and MoveIt resolve its
package:// mesh URIs on any machine.

`so101-description install PREFIX` writes an ament prefix with one package, so101_description:
its URDF (so101_state_publisher --print-urdf, mesh URIs package://so101_description/meshes/...),
the fetched mesh files, and the RViz configuration (assets/rviz/so101.rviz). Add the prefix to
AMENT_PREFIX_PATH (the command prints the line) wherever RViz runs: ROS looks packages up there.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

from ..paths import asset, node_binary

PACKAGE = "so101_description"
RVIZ_CONFIG = "rviz/so101.rviz"  # under assets/ and under the package's share directory
MESH_DIR = "third_party/so101"  # under assets/: where the set-up fetches the meshes

PACKAGE_XML = f"""<?xml version="1.0"?>
<package format="3">
  <name>{PACKAGE}</name>
  <version>0.1.0</version>
  <description>SO-101 arm description (URDF, meshes, RViz view) installed by so101-description</description>
  <maintainer email="so101@localhost">SO-101 ROS 2 stack</maintainer>
  <license>Apache-2.0</license>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""


def share_directory(prefix: Path) -> Path:
    return prefix / "share" / PACKAGE


def install(prefix: Path) -> Path:
    """Writes the package into `prefix` (replacing an earlier install); returns its share
    directory. The URDF is so101_state_publisher's, with package:// mesh URIs."""
    share = share_directory(prefix)
    if share.exists():
        shutil.rmtree(share)
    (share / "meshes").mkdir(parents=True)
    (share / "urdf").mkdir()
    (share / "rviz").mkdir()
    # The marker ament_index looks for: the package exists in this prefix.
    index = prefix / "share" / "ament_index" / "resource_index" / "packages"
    index.mkdir(parents=True, exist_ok=True)
    (index / PACKAGE).write_text("")
    (share / "package.xml").write_text(PACKAGE_XML)
    meshes = asset(MESH_DIR)
    for mesh in sorted(meshes.glob("*.stl")) if meshes.is_dir() else []:
        shutil.copy2(mesh, share / "meshes" / mesh.name)
    if meshes.joinpath("LICENSE").is_file():
        shutil.copy2(meshes / "LICENSE", share / "meshes" / "LICENSE")
    urdf = subprocess.run(
        [str(node_binary("so101_state_publisher")), "--print-urdf", "--mesh-uri", "package"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    (share / "urdf" / "so101.urdf").write_text(urdf)
    shutil.copy2(asset(RVIZ_CONFIG), share / RVIZ_CONFIG)
    return share


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="so101-description", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    commands = parser.add_subparsers(dest="command", required=True)
    install_command = commands.add_parser("install", help="write the so101_description package into PREFIX")
    install_command.add_argument("prefix", type=Path, help="an ament prefix directory (created if missing)")
    args = parser.parse_args(argv)
    prefix = args.prefix.resolve()
    share = install(prefix)
    meshes = len(list((share / "meshes").glob("*.stl")))
    print(f"so101-description: {PACKAGE} installed in {prefix} ({meshes} meshes)")
    if not meshes:
        print(
            "so101-description: no meshes found (run the set-up to fetch them): RViz draws the collision boxes", file=sys.stderr
        )
    print(f"export AMENT_PREFIX_PATH={prefix}${{AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}}")
    print(f"rviz2 -d {share / RVIZ_CONFIG}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
