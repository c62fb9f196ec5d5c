"""A PCD depth frame imported through the operator in real Blender: the NaN rows dropped and
said, colours and intensity as attributes, the VIEWPOINT as the scanner position that the
estimated normals face."""
from __future__ import annotations

import numpy as np
from pypcd4 import Encoding, PointCloud as Pcd

from frames import slanted_wall_frame
from splat_tracer.util.matrices import quaternion_matrices


def test_a_pcd_depth_frame_imports_with_its_viewpoint(blender, empty_scene, tmp_path):
    bpy = blender
    assert ".pcd" in bpy.types.SPLAT_TRACER_FH_point_cloud.bl_file_extensions.split(";")
    q, t = np.array([0.9, -0.2, 0.3, 0.1]), np.array([-3.0, 5.0, 1.5])
    camera, _ = slanted_wall_frame()
    world = (camera @ quaternion_matrices(q[None] / np.linalg.norm(q))[0].T + t).astype(np.float32)
    n = len(world)
    rgb = np.full(n, (200 << 16) | (100 << 8) | 50, np.uint32)
    intensity = np.linspace(0, 1, n, dtype=np.float32)
    cloud = Pcd.from_points([world[:, 0], world[:, 1], world[:, 2], rgb.view(np.float32), intensity],
                            ("x", "y", "z", "rgb", "intensity"), (np.float32,) * 5)
    cloud.metadata = cloud.metadata.derive(width=160, height=120, viewpoint=(*t, *(q / np.linalg.norm(q))))
    path = tmp_path / "frame.pcd"
    cloud.save(str(path), encoding=Encoding.BINARY_COMPRESSED)

    assert bpy.ops.splat_tracer.import_cloud(filepath=str(path)) == {"FINISHED"}
    obj = bpy.context.active_object
    holes = int(np.isnan(camera[:, 0]).sum())
    assert obj["splat_tracer_format"] == "PCD" and len(obj.data.vertices) == n - holes > 0
    notes = obj["splat_tracer_import_notes"]
    assert f"{holes:,} rows with non-finite coordinates were dropped" in notes, notes
    assert "the sensor's position from the file's VIEWPOINT: (-3, 5, 1.5)" in notes, notes
    attrs = obj.data.attributes
    m = len(obj.data.vertices)
    co, normal, scanner = (np.empty(m * 3, np.float32) for _ in range(3))
    attrs["position"].data.foreach_get("vector", co)
    attrs["splat_normal"].data.foreach_get("vector", normal)
    attrs["scanner_position"].data.foreach_get("vector", scanner)
    location = np.array(obj.location)
    np.testing.assert_allclose(scanner.reshape(-1, 3) + location, np.broadcast_to(t, (m, 3)), atol=1e-4)
    points = co.reshape(-1, 3) + location
    facing = np.einsum("ij,ij->i", normal.reshape(-1, 3), t - points) > 0
    assert facing.mean() >= 0.99, facing.mean()
    values = np.empty(m, np.float32)
    attrs["intensity"].data.foreach_get("value", values)
    assert attrs["intensity"].data_type == "FLOAT" and np.isin(values, intensity).all()
    colour = np.empty(m * 4, np.float32)
    attrs["splat_color"].data.foreach_get("color", colour)
    srgb = np.array([200, 100, 50]) / 255.0
    np.testing.assert_allclose(colour.reshape(-1, 4)[0, :3], ((srgb + 0.055) / 1.055) ** 2.4, rtol=1e-5)
