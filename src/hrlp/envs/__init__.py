"""What hrlp knows of any environment: parameterised action spaces (:mod:`~hrlp.envs.actions`), the checks of a task
and its spaces (:mod:`~hrlp.envs.check`), the vector-environment seam (:mod:`~hrlp.envs.vector`), and hrlp's small
parameterised-action tasks (:mod:`~hrlp.envs.param_tasks`, registered as ``hrlp/<Name>-v0`` on import). The arm with a
claw is a domain of its own: :mod:`hrlp.arm`."""

from hrlp.envs.param_tasks import register_param_tasks

register_param_tasks()

__all__ = ["register_param_tasks"]
