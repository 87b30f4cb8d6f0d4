"""Learning algorithms: batched actor–critic models, returns (eqs. 12–13) and the learner.

- :class:`ActorCritic` / :func:`make_model`: N actors with one critic (A2CM) or N (A2C).
- :func:`discounted_returns` / :func:`advantages`: time-major targets.
- :class:`Learner`: RMSprop step on one batch; :class:`NonFiniteLoss` when the loss blows up.
"""

from a2cm_phys.algos.learner import BATCH_KEYS, Learner, NonFiniteLoss
from a2cm_phys.algos.models import (
    ActorCritic,
    PackedParams,
    StackedLinear,
    make_model,
    sample_categorical,
)
from a2cm_phys.algos.returns import advantages, discounted_returns, discounted_returns_np

__all__ = [
    "BATCH_KEYS",
    "ActorCritic",
    "Learner",
    "NonFiniteLoss",
    "PackedParams",
    "StackedLinear",
    "advantages",
    "discounted_returns",
    "discounted_returns_np",
    "make_model",
    "sample_categorical",
]
