"""Bandai-Namco-2's files: clip names, styles, the protocol's rates and lengths, where the tarball is extracted.

Shared by the joint loader (`datasets.load_bandai`) and the marker loader (`markers.load_bandai_markers`).
"""

from __future__ import annotations

import os
import re
import shutil
import tarfile
from pathlib import Path

from jaxmotion.errors import DataError

# Bandai-Namco-2 (BVH, centimetres, Y up)

BANDAI_TARBALL = "bandai2_dev.tar.xz"
BANDAI_TRAIN_STYLES = ("active", "exhausted", "feminine", "masculine")
BANDAI_TEST_STYLES = ("normal",)
# protocol §4 (docs/pages/protocol.md#datasets), shared by the joint (`load_bandai`) and marker (`load_bandai_markers`) datasets.
BANDAI_PROTOCOL = {"fps": 30.0, "t_his": 15, "t_pred": 60, "mm_threshold": 0.5}
# A clip's file stem: `dataset-2_{content}_{style}_{id}`.
BANDAI_NAME = re.compile(r"^dataset-2_(?P<content>[^_]+)_(?P<style>[^_]+)_(?P<id>\d+)$")


def default_cache_dir() -> Path:
    """Returns the folder the Bandai tarball is extracted into: `$XDG_CACHE_HOME/jaxmotion/bandai2`."""
    return Path(os.environ.get("XDG_CACHE_HOME", "~/.cache")).expanduser() / "jaxmotion" / "bandai2"


def bandai_clip_dir(root: Path, cache_dir: str | os.PathLike | None) -> Path:
    """Returns the folder of extracted clips, extracting the tarball into the cache if needed."""
    tarball = root / BANDAI_TARBALL
    if not tarball.is_file():
        if not root.is_dir():
            raise FileNotFoundError(f"{root}: no such folder (expected {BANDAI_TARBALL} or extracted clips)")
        return root
    cache = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()
    done = cache / ".extracted"
    stamp = str(tarball.stat().st_size)
    if done.is_file() and done.read_text().strip() == stamp:
        return cache
    if cache.exists() and not done.is_file() and any(cache.iterdir()):
        # Never delete a folder this loader did not fill.
        raise ValueError(f"{cache}: cache folder exists but holds no extraction of {tarball}; remove it")
    # Extract into a private folder and rename, so an interrupted or concurrent extraction never
    # leaves a half-filled cache that a later run would trust.
    cache.parent.mkdir(parents=True, exist_ok=True)
    tmp = cache.parent / f".{cache.name}.tmp-{os.getpid()}"
    try:
        with tarfile.open(tarball) as tf:
            tf.extractall(tmp, filter="data")
    except (tarfile.TarError, EOFError, OSError) as e:
        shutil.rmtree(tmp, ignore_errors=True)
        raise DataError(tarball, f"cannot extract ({type(e).__name__}: {e})") from e
    (tmp / ".extracted").write_text(stamp)
    if cache.exists():  # empty, or a stale extraction of an older tarball
        shutil.rmtree(cache, ignore_errors=True)
    try:
        tmp.rename(cache)
    except OSError:
        shutil.rmtree(tmp, ignore_errors=True)
        if not (done.is_file() and done.read_text().strip() == stamp):
            raise
        # Another process finished the same extraction first; use theirs.
    return cache
