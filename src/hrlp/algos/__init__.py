"""TRPO built from small pure kernels (flat gradient, Fisher-vector product, CG, step size, line search, GAE)."""

from hrlp.algos.kernels import (
    GAEResult,
    LineSearchResult,
    backtracking_line_search,
    conjugate_gradient,
    discounted_returns,
    explained_variance,
    fisher_vector_product,
    flat_grad,
    gae,
    get_flat_params,
    make_fisher_vector_product,
    max_step_length,
    set_flat_params,
    standardize,
)
from hrlp.algos.trpo import TRPOConfig, TRPOStats, surrogate_objective, trpo_update
from hrlp.algos.value import ValueFitConfig, ValueFitStats, fit_value

__all__ = [
    "GAEResult",
    "LineSearchResult",
    "TRPOConfig",
    "TRPOStats",
    "ValueFitConfig",
    "ValueFitStats",
    "backtracking_line_search",
    "conjugate_gradient",
    "discounted_returns",
    "explained_variance",
    "fisher_vector_product",
    "fit_value",
    "flat_grad",
    "gae",
    "get_flat_params",
    "make_fisher_vector_product",
    "max_step_length",
    "set_flat_params",
    "standardize",
    "surrogate_objective",
    "trpo_update",
]
