# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/dlow_bandai_val_h36m.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/val/dlow_h36m_s0 --seed 0
#
# One variant of the validation sweep of DLow's d_scale: dlow_bandai_val.py says which and why.
import importlib.util
from pathlib import Path

_spec = importlib.util.spec_from_file_location("dlow_bandai_val", Path(__file__).with_name("dlow_bandai_val.py"))
_sweep = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_sweep)


def get_config():
    return _sweep.variant("h36m")
