# Two processes on one machine, joined by jax.distributed over 127.0.0.1 (docs/pages/distributed.md):
#   export JAX_PLATFORMS=cpu && mkdir -p runs
#   jaxmotion run --config experiments/configs/dlow_two_processes.py --workdir runs/two_processes \
#       --coordinator-address 127.0.0.1:12355 --num-processes 2 --process-id 1 > runs/two_processes.p1.log 2>&1 &
#   jaxmotion run --config experiments/configs/dlow_two_processes.py --workdir runs/two_processes \
#       --coordinator-address 127.0.0.1:12355 --num-processes 2 --process-id 0
# A small DLow on the synthetic data, to try the multi-process path, not a result: CVAE 100 steps x 64
# (32 windows per process), Q network 40 steps x 16, K = 5 on 64 test windows.
# The speed of two processes against one: docs/pages/benchmarks.md ("Scaling over devices and processes", measured with benchmarks/scaling.py).
from jaxmotion.config import Config
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig


def get_config() -> Config:
    return Config(
        name="dlow_two_processes",
        method_config=DLowConfig(
            cvae=CVAEConfig(num_steps=100, batch_size=64, nz=32, nh_rnn=32, nh_mlp=(64,)),
            q=QConfig(num_steps=40, batch_size=16, nh_rnn=32, nh_mlp=(64,)),
        ),
        eval_k=(5,),
        max_test_windows=64,
        ckpt_every=50,
        log_every=20,
    )
