"""Motion clips shipped with jaxmotion, so that the documentation's examples run after `pip install`.

    from jaxmotion.examples import cmu_clip
    jaxmotion predict --model bandai "$(python -c 'import jaxmotion.examples as e; print(e.cmu_clip())')" --out futures/

`cmu_01_01.bvh`: subject 01, trial 01 of the CMU Graphics Lab Motion Capture Database (mocap.cs.cmu.edu),
in the cgspeed BVH conversion: its first 10 s (1,200 frames at 120 fps) with every fourth frame kept,
300 frames at 30 fps; 31 joints, CMU naming, CMU units (0.056444 m per unit, recognised by
`formats.bvh.guess_scale`). CMU's terms: free for research and commercial use; "The data used in this
project was obtained from mocap.cs.cmu.edu. The database was created with funding from NSF EIA-0196217."
The BVH conversion (B. Hahne, cgspeed.com) adds no restriction.
"""

from __future__ import annotations

from pathlib import Path

CLIPS = {"cmu_01_01": "cmu_01_01.bvh"}


def cmu_clip(name: str = "cmu_01_01") -> Path:
    """Returns the path of a shipped example clip (`CLIPS`), a BVH file that `jaxmotion predict` and `read_motion` read."""
    if name not in CLIPS:
        raise FileNotFoundError(f"{name}: not a shipped example clip (shipped: {sorted(CLIPS)})")
    path = Path(__file__).resolve().parent / CLIPS[name]
    if not path.is_file():
        raise FileNotFoundError(f"{path}: the example clip {name!r} is missing from this installation")
    return path
