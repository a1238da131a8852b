"""CPU host devices: one process's CPU as N XLA devices (`jaxmotion run --host-devices N`).

XLA's CPU backend gives a process N devices when `XLA_FLAGS` holds `--xla_force_host_platform_device_count=N`
as jax's backend starts; each device runs its own stream of XLA operations, and a step data-parallel over
them (`jaxmotion.train.distributed`) keeps cores busy that one stream of small operations leaves idle
(docs/pages/distributed.md, "Several host devices on one CPU"). The flag takes effect only
before anything has run on a device: `force_host_devices` sets it, `check_host_devices` checks afterwards
that it took effect. `host_device_flags` / `host_device_env` give a process started from this one the flag.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping

from jaxmotion.errors import UsageError

HOST_DEVICES_FLAG = "--xla_force_host_platform_device_count"


def host_device_flags(flags: str, n: int) -> str:
    """Returns the XLA flags `flags` with `n` CPU host devices added (the flags set before stay as they are)."""
    return f"{flags} {HOST_DEVICES_FLAG}={n}".strip()


def host_device_env(env: Mapping[str, str], n: int) -> dict[str, str]:
    """Returns a copy of the environment `env` whose `XLA_FLAGS` give a process started with it `n` CPU host devices."""
    return dict(env, XLA_FLAGS=host_device_flags(env.get("XLA_FLAGS", ""), n))


def force_host_devices(n: int) -> None:
    """Gives this process `n` CPU host devices: sets `XLA_FLAGS`, which XLA reads when jax's CPU backend starts,
    so call it before anything runs on a device (then `check_host_devices`).

    Raises:
        jaxmotion.errors.UsageError: `XLA_FLAGS` already sets another count.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    given = re.findall(HOST_DEVICES_FLAG + r"=(\d+)", flags)
    if given and int(given[-1]) != n:
        raise UsageError(f"--host-devices {n}: XLA_FLAGS already sets {HOST_DEVICES_FLAG}={given[-1]}; give one of them")
    if not given:
        os.environ["XLA_FLAGS"] = host_device_flags(flags, n)


def check_host_devices(n: int) -> None:
    """Checks that `force_host_devices(n)` took effect; starts jax's backend if it has not started (after
    `jax.distributed.initialize`, where a job has several processes).

    Raises:
        jaxmotion.errors.UsageError: jax runs on another platform than the CPU, or its CPU backend had started with
            another device count before the flag was set.
    """
    import jax

    devices = jax.local_devices()
    if devices[0].platform != "cpu":
        raise UsageError(f"--host-devices splits steps over CPU host devices; jax runs on {devices[0].platform} here "
                         f"({len(devices)} devices, all used already)")
    if len(devices) != n:
        raise UsageError(f"--host-devices {n}: jax's CPU backend had already started with {len(devices)} device(s) in "
                         f"this process; run the command in a new process, or set XLA_FLAGS={HOST_DEVICES_FLAG}={n} "
                         f"before jax starts")
