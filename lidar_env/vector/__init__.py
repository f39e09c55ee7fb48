"""The batched ``DualLidar-v0``: N cars stepped in one compiled call, bit-identical to N single
envs in a ``gymnasium.vector.SyncVectorEnv``.

``gym.make_vec("DualLidar-v0", num_envs=N, vectorization_mode="vector_entry_point")`` returns a
:class:`DualLidarVectorEnv` (:mod:`.env`); :mod:`.kernel` holds its compiled step (called through
:mod:`.entry_point`), :mod:`.slots` the per-env scenes and generators the kernel reads,
:mod:`.crowds` the per-env moving obstacles, :mod:`.draws` numpy's normal and uniform draws
compiled over each generator's state and :mod:`.unowned` the views the kernel's loops over envs
take of its arguments (no reference counting). This package imports only from ``lidar_env`` (the
single env's car, Lidar layout, movers, scenes and trace geometry), never from ``estimators`` or
``agents``.
"""

from lidar_env.vector.env import DualLidarVectorEnv, not_batched

__all__ = ["DualLidarVectorEnv", "not_batched"]
