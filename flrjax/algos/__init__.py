"""The training methods, each one module of pure per-run functions the trainer vmaps and scans,
registered by name (:mod:`flrjax.algos.registry`): importing this package registers the
built-in ones."""

# Each registers its methods, in this order (--help's and messages').
from flrjax.algos import flat, dhrl, pig, higl  # noqa: F401  # isort: skip
from flrjax.algos.registry import Method, get, methods, names, point_method, register, unregister

#: ``--algo`` when not given: the paper's method.
DEFAULT = "flr_dhrl"

__all__ = ["DEFAULT", "Method", "get", "methods", "names", "point_method", "register", "unregister"]
