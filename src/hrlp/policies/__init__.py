"""Action distributions (Gaussian, categorical, the Manager's hierarchical one), MLP policies, value net, normaliser."""

from hrlp.policies.distributions import (
    Categorical,
    DiagGaussian,
    Distribution,
    Hierarchical,
    flat_to_tuple,
    flat_to_tuples,
    tuple_to_flat,
    tuples_to_flat,
)
from hrlp.policies.mlp import CategoricalPolicy, GaussianPolicy, HierarchicalPolicy, NumpyMLP, Policy, ValueNet, mlp
from hrlp.policies.normalizer import RunningNormalizer

__all__ = [
    "Categorical",
    "CategoricalPolicy",
    "DiagGaussian",
    "Distribution",
    "GaussianPolicy",
    "Hierarchical",
    "HierarchicalPolicy",
    "NumpyMLP",
    "Policy",
    "RunningNormalizer",
    "ValueNet",
    "flat_to_tuple",
    "flat_to_tuples",
    "mlp",
    "tuple_to_flat",
    "tuples_to_flat",
]
