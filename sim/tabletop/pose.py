"""What a 3D view needs: each present object's mesh name, colour and pose, and their poses over
simulated time during a pick-and-place. Meshes come from sim.tabletop.meshes.shape_mesh."""

from __future__ import annotations

from sim.core import Scene
from sim.core.view3d import ObjectPose
from sim.tabletop.colours import TABLE_RGB
from sim.tabletop.textures import mean_rgb

TABLE_TOP_Z_M = 0.0
TABLE_HALF_M = 0.6  # the table top is the square [-0.6, 0.6]^2 at z = 0 (matches the model)
TABLE_THICKNESS_M = 0.04
TABLE_RGBA = (*(c / 255 for c in TABLE_RGB), 1.0)


def rgba(colour: str) -> tuple[float, float, float, float]:
    """A colour's display RGBA in [0, 1] (textures: their mean colour)."""
    r, g, b = mean_rgb(colour)
    return (r / 255, g / 255, b / 255, 1.0)


def object_poses(scene: Scene) -> list[ObjectPose]:
    """The present objects of a scene, in slot order (no MuJoCo needed)."""
    out = []
    for o in scene.objects:
        if not o.present:
            continue
        p = o.pos
        assert len(p) == 7, f"tabletop Obj.pos is (x, y, z, qw, qx, qy, qz), got {p}"
        colour = o.value("colour")
        out.append(
            ObjectPose(
                o.slot,
                o.value("shape"),
                colour,
                rgba(colour),
                (p[0], p[1], p[2]),
                (p[3], p[4], p[5], p[6]),
            )
        )
    return out
