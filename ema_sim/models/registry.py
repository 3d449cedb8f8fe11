"""Models by name, as table 5 lists them; an unknown name is an error that lists the known ones."""

from __future__ import annotations

from collections.abc import Callable
from importlib import import_module

from ema_sim.config import ChannelConfig
from ema_sim.errors import UnknownNameError
from ema_sim.models.base import ActuatorModel
from ema_sim.parameters import ParameterInfo

_MODELS: dict[str, str] = {
    "loac": "ema_sim.models.second_order.models:Loac",
    "loadf": "ema_sim.models.second_order.models:Loadf",
    "loada": "ema_sim.models.second_order.models:Loada",
    "hoac1": "ema_sim.models.high_order.models:Hoac1",
    "hoad2": "ema_sim.models.high_order.models:Hoad2",
    "hoad3": "ema_sim.models.high_order.models:Hoad3",
    "sloac": "ema_sim.models.linear:Sloac",
    "hoalm": "ema_sim.models.linear:Hoalm",
    "loes": "ema_sim.models.linear:Loes",
    "second_order": "ema_sim.models.second_order.models:SecondOrder",
}
"""Registry name → ``module:class`` (imported on first use, so listing names stays cheap)."""


def model_names() -> list[str]:
    """The names ``create`` accepts, in table 5's order.

    Returns
    -------
    list of str
        Registry names.
    """
    return list(_MODELS)


def model_class(name: str) -> type[ActuatorModel]:
    """The class registered under ``name``.

    Parameters
    ----------
    name : str
        Registry name (case and surrounding spaces ignored).

    Returns
    -------
    type
        The model class.
    """
    key = name.strip().lower()
    if key not in _MODELS:
        raise UnknownNameError("model", name, _MODELS)
    module, cls = _MODELS[key].split(":")
    found: type[ActuatorModel] = getattr(import_module(module), cls)
    return found


def create(name: str, channel: str | ChannelConfig = "left_wing", **kwargs: object) -> ActuatorModel:
    """Build model ``name`` for ``channel``.

    Parameters
    ----------
    name : str
        Registry name (:func:`model_names`).
    channel : str or ChannelConfig
        Channel name, or a channel's configuration (one a record changed, its travel say).
    **kwargs : object
        ``n``, ``rate_hz``, options and parameter overrides, passed to the class.

    Returns
    -------
    ActuatorModel
        The model, trimmed at zero.
    """
    make: Callable[..., ActuatorModel] = model_class(name)  # each family's constructor has keywords of its own
    return make(channel, **kwargs)


def model_parameters(name: str, channel: str | ChannelConfig | None = None) -> list[ParameterInfo]:
    """Every parameter of model ``name``: name, YAML path, unit, range, description, switch, kernel slot.

    The one listing identification bounds, Monte Carlo dispersions and ROS parameter descriptors read
    (:func:`ema_sim.parameters.describe`).

    Parameters
    ----------
    name : str
        Registry name.
    channel : str or ChannelConfig, optional
        The channel whose values are listed as each parameter's ``default``.

    Returns
    -------
    list of ParameterInfo
        In declaration order.
    """
    return model_class(name).parameters(channel)
