"""The base of every config model: frozen, unknown keys rejected; the vector types configs use."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict

__all__ = ["Q6", "ConfigModel", "Vec3"]

Vec3 = tuple[float, float, float]
Q6 = tuple[float, float, float, float, float, float]


class ConfigModel(BaseModel):
    """A section of a config: immutable once loaded; a key it does not define is an error."""

    model_config = ConfigDict(extra="forbid", frozen=True)
