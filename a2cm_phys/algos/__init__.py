"""Learning algorithms: action distributions, batched actor–critic models, returns and the
learner.

- :mod:`.distributions`: categorical and diagonal-Gaussian actions behind one interface.
- :class:`ActorCritic` / :func:`make_model`: N actors with one critic (A2CM) or N (A2C).
- :func:`gae` / :func:`discounted_returns`: time-major advantages and returns (eqs. 12–13).
- :class:`ValueNorm`: PopArt-style running normalisation of value targets per component.
- :class:`Learner`: one autograd loss and optimiser step; :class:`NonFiniteLoss`.
"""

from .build import action_distribution, make_model
from .distributions import (
    ActionDistribution,
    CategoricalActions,
    GaussianActions,
    sample_categorical,
)
from .layers import StackedLinear
from .learner import BATCH_KEYS, Learner
from .losses import NonFiniteLoss
from .models import ActorCritic
from .normalize import ValueNorm
from .returns import advantages, discounted_returns, discounted_returns_np, gae

__all__ = [
    "BATCH_KEYS",
    "ActionDistribution",
    "ActorCritic",
    "CategoricalActions",
    "GaussianActions",
    "Learner",
    "NonFiniteLoss",
    "StackedLinear",
    "ValueNorm",
    "action_distribution",
    "advantages",
    "discounted_returns",
    "discounted_returns_np",
    "gae",
    "make_model",
    "sample_categorical",
]
