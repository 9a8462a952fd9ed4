"""Training, one module per job: building environments (:mod:`~hrlp.training.environments`), loading runs
(:mod:`~hrlp.training.loading`), logging (:mod:`~hrlp.training.logs`) and the loop (:mod:`~hrlp.training.loop`);
:mod:`hrlp.train` re-exports them, with the settings of :mod:`hrlp.config`."""


def __getattr__(name: str) -> object:
    """``hrlp.training.from_run`` (:func:`hrlp.training.loading.from_run`), imported on first use: the package itself
    stays light, as ``hrlp --help`` needs."""
    if name == "from_run":
        from hrlp.training.loading import from_run

        return from_run
    raise AttributeError(f"module 'hrlp.training' has no attribute {name!r}")


__all__ = ["from_run"]
