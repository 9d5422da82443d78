"""The truth a controller acts on (layer `plant`): the plant with its true φ and disturbance (:mod:`.plant`), actuators
(:mod:`.actuators`), sensors (:mod:`.sensors`) and unmodeled dynamics (:mod:`.unmodeled`)."""

from .plant import Plant, SinusoidalDisturbance, sinusoidal_disturbance

__all__ = ["Plant", "SinusoidalDisturbance", "sinusoidal_disturbance"]
