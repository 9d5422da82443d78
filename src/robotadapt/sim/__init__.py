"""The closed loop and its integrators (layer `sim`): one step function (:mod:`.loop`), fixed-step RK4, solve_ivp and
sampled-data drivers (:mod:`.simulation`, :mod:`.sampled`), the compiled engine (:mod:`.compiled`), batches (:mod:`.batch`)
and the result record (:mod:`.result`)."""

from .batch import NotBatchable, simulate_batch
from .integrators import RK4, Sampled, SolveIVP
from .result import SimulationResult
from .simulation import simulate

__all__ = ["RK4", "NotBatchable", "Sampled", "SimulationResult", "SolveIVP", "simulate", "simulate_batch"]
