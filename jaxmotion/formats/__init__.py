"""File formats: motion capture parsers and helpers that need nothing but numpy.

- `bvh.read_bvh` / `bvh.forward_kinematics`: BVH skeletons and motion; `bvh.guess_scale` (metres
  per file unit), `bvh.is_ground_node` (a constant root like Bandai's `joint_Root`) and
  `bvh.is_ground_skeleton` (the same decided from the skeleton alone, once per folder).
- `bvh_write.write_bvh` / `bvh_write.matrix_to_euler`: writing BVH files (the inverse of `bvh`).
- `c3d.read_c3d`: labelled C3D marker trajectories with their gaps.
- `npz.read_arrays` / `npz.read_array_dict`: a user's `.npz` without running code from it (plain arrays;
  VideoPose3D's pickled dict of arrays through an unpickler that builds nothing else).

This is the lowest layer: `formats <- body <- data` (body models read BVH files, dataset loaders
use both). Nothing here imports `jaxmotion.body` or `jaxmotion.data`, not even `data.types`: a
parsed file carries its own names and parents (`Bvh.names`, `Bvh.parents`), and turning them into a
dataset `Skeleton` is the loaders' job. `tests/test_layers.py` checks the direction.
"""
