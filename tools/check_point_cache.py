# Opens a rest mesh (OBJ) with a point cache (PC2 or MDD) in Blender, the way a user does
# (File > Import > Wavefront with its default axes, then a Mesh Cache modifier with its
# defaults), and writes the mesh's vertices at one scene frame as little-endian f32 x, y, z
# in the files' own axes (the object's local coordinates).
# Usage: blender -b --python tools/check_point_cache.py -- REST.obj CACHE FRAME OUT.bin
import struct
import sys

import bpy

rest, cache, frame, out = sys.argv[sys.argv.index("--") + 1 :]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.obj_import(filepath=rest)
obj = bpy.context.selected_objects[0]
modifier = obj.modifiers.new("point cache", "MESH_CACHE")
modifier.cache_format = "MDD" if cache.lower().endswith(".mdd") else "PC2"
modifier.filepath = cache
bpy.context.scene.frame_set(int(frame))
mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
with open(out, "wb") as f:
    for v in mesh.vertices:
        f.write(struct.pack("<3f", *v.co))
print(f"point cache: {len(mesh.vertices)} vertices at frame {frame} written to {out}")
