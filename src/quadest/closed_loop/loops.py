"""The closed loops, one per model a controller can fly on its filter state. Each loop class names
the ``model`` option it flies (``model_name``, read from that model's spec); nothing else lists
model names."""

from __future__ import annotations

from quadest.closed_loop.quadrotor import QuadrotorLoop
from quadest.closed_loop.seed003 import Seed003Loop
from quadest.config.settings import DataSettings

LOOP_CLASSES: tuple[type[QuadrotorLoop], ...] = (QuadrotorLoop, Seed003Loop)


def controlled_models() -> list[str]:
    """The ``model`` options with a closed loop (``loop`` other than ``open``)."""
    return [cls.model_name for cls in LOOP_CLASSES]


def closed_loop_for(settings: DataSettings) -> QuadrotorLoop:
    """The closed loop of ``settings.model`` (one of :func:`controlled_models`, checked by
    :func:`quadest.config.closed_loop.validate_loop` before any work)."""
    by_model = {cls.model_name: cls for cls in LOOP_CLASSES}
    return by_model[settings.model.name].from_settings(settings)
