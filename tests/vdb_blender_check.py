# Blender half of tests/vdb_blender_check.sh, run as
#   blender -b --factory-startup --python tests/vdb_blender_check.py -- FILE.vdb XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX
# Imports FILE.vdb the way a user does (File > Import > OpenVDB: bpy.ops.object.volume_import) and checks:
# - the scene gains one volume object holding one grid, named "density" (what Blender's volume shading
#   reads by default);
# - the surface of that volume (Blender's Volume to Mesh at threshold 0.5, i.e. the boundary of the lit
#   voxels) has the model's bounds (the expected box, model mm) within one voxel on every side;
# - Blender's own bounding box of the volume object holds that box; Blender computes it from whole leaf
#   nodes (8 voxels), so it may exceed the model by up to 8 voxels, never more.
# Prints one PASS or FAIL line; exits 0 on PASS, 1 on FAIL (Blender itself exits 0 after --python).
import os
import sys

import bpy


def main():
    args = sys.argv[sys.argv.index("--") + 1:]
    path = os.path.abspath(args[0])
    expected = [float(v) for v in args[1].split(",")]
    lo, hi = expected[:3], expected[3:]
    problems = []

    bpy.ops.object.volume_import(filepath=path, directory=os.path.dirname(path),
                                 files=[{"name": os.path.basename(path)}])
    volumes = [o for o in bpy.context.scene.objects if o.type == 'VOLUME']
    if len(volumes) != 1:
        return [f"{len(volumes)} volume objects after the import, expected 1"], ""
    volume = volumes[0]
    depsgraph = bpy.context.evaluated_depsgraph_get()
    grids = volume.evaluated_get(depsgraph).data.grids
    names = [(g.name, g.data_type) for g in grids]
    if grids.error_message:
        problems.append("Blender could not read the grids: " + grids.error_message)
    if len(grids) != 1 or grids[0].name != "density":
        problems.append(f"grids {names}, expected one named 'density'")
    if problems:
        return problems, ""
    m = grids[0].matrix_object
    voxel = [abs(m[0][0]), abs(m[1][1]), abs(m[2][2])]

    surface = bpy.data.objects.new("surface", bpy.data.meshes.new("surface"))
    bpy.context.scene.collection.objects.link(surface)
    modifier = surface.modifiers.new("to mesh", 'VOLUME_TO_MESH')
    modifier.object = volume
    modifier.grid_name = "density"
    modifier.threshold = 0.5
    modifier.resolution_mode = 'GRID'
    depsgraph = bpy.context.evaluated_depsgraph_get()
    vertices = surface.evaluated_get(depsgraph).data.vertices
    if len(vertices) == 0:
        return ["Volume to Mesh gave no surface"], ""
    got_lo = [min(v.co[a] for v in vertices) for a in range(3)]
    got_hi = [max(v.co[a] for v in vertices) for a in range(3)]
    corners = [tuple(c) for c in volume.evaluated_get(depsgraph).bound_box]
    box_lo = [min(c[a] for c in corners) for a in range(3)]
    box_hi = [max(c[a] for c in corners) for a in range(3)]
    eps = 1e-4
    for a, axis in enumerate("xyz"):
        if abs(got_lo[a] - lo[a]) > voxel[a] + eps or abs(got_hi[a] - hi[a]) > voxel[a] + eps:
            problems.append(f"surface {axis} {got_lo[a]:.5f}..{got_hi[a]:.5f}, model {lo[a]:.5f}..{hi[a]:.5f}, "
                            f"voxel {voxel[a]:.5f}")
        if box_lo[a] > lo[a] + voxel[a] + eps or box_hi[a] < hi[a] - voxel[a] - eps or \
                box_lo[a] < lo[a] - 8 * voxel[a] - eps or box_hi[a] > hi[a] + 8 * voxel[a] + eps:
            problems.append(f"bounding box {axis} {box_lo[a]:.5f}..{box_hi[a]:.5f}, model {lo[a]:.5f}..{hi[a]:.5f}")
    detail = (f"one volume, grid {names[0]}, surface bounds {[round(v, 4) for v in got_lo]}.."
              f"{[round(v, 4) for v in got_hi]} vs model {lo}..{hi} (voxel {[round(v, 5) for v in voxel]}), "
              f"Blender box {[round(v, 4) for v in box_lo]}..{[round(v, 4) for v in box_hi]}")
    return problems, detail


try:
    problems, detail = main()
except Exception as e:  # any Blender or argument error is a failure, not a crash with exit status 0
    problems, detail = [f"{type(e).__name__}: {e}"], ""
name = sys.argv[sys.argv.index("--") + 1] if "--" in sys.argv else "?"
if problems:
    print(f"FAIL: blender {name}: " + "; ".join(problems), flush=True)
    sys.exit(1)
print(f"PASS: blender {name}: {detail}", flush=True)
sys.exit(0)
