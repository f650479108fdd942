"""Material electromagnetic parameters: the ITU-R P.2040-3 table plus literature values.

Every material is a list of rows ``(f_min, f_max, a, b, c, d)`` valid over ``[f_min, f_max]``
[GHz], with the ITU-R P.2040-3 power laws (Section 2.1.4 and Table 3)::

    eps_r'(f) = a * f**b          relative permittivity, real part [-]
    sigma(f)  = c * f**d          conductivity [S/m]          (f in GHz)

and the complex relative permittivity (ITU-R P.2040-3, eq. (9b))::

    eta = eps_r' - j * sigma / (omega * eps0) = eps_r' - j * 17.98 * sigma / f_GHz

Sources
-------
* ITU rows: ITU-R P.2040-3 (08/2023), Table 3 "Material properties".
* ``ceramic_tile``, ``plastic``, ``fabric``: no ITU row exists; representative mm-wave values
  from the literature, entered as (eps', tan delta) and converted to ``c, d`` by
  ``sigma = 2*pi*f*eps0*eps'*tan(delta)`` (so ``d = 1``). Treat them as +-20 %.
* ``unknown``: a documented default (see :data:`MATERIALS`), chosen mid-way between the light
  (wood, plasterboard) and dense (concrete, brick) building materials of Table 3.

Names are case-insensitive; spaces and hyphens count as underscores
(``"Ceiling board"`` == ``"ceiling_board"``).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping
from types import MappingProxyType

from sim2radar.constants import VACUUM_PERMITTIVITY_F_M

__all__ = [
    "MaterialRow",
    "Material",
    "MATERIALS",
    "MaterialFrequencyWarning",
    "UnknownMaterialError",
    "material_names",
    "get_material",
    "normalize_material_name",
    "material_parameters",
    "complex_permittivity",
]


class MaterialFrequencyWarning(UserWarning):
    """A material was evaluated outside the frequency range of its table row(s)."""


class UnknownMaterialError(KeyError):
    """A material name is not in :data:`MATERIALS`; the message lists the known names."""

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0])


@dataclasses.dataclass(frozen=True)
class MaterialRow:
    """One ITU-R P.2040 style row: ``eps' = a f^b``, ``sigma = c f^d`` for f in [GHz].

    Attributes
    ----------
    f_min_ghz, f_max_ghz : float
        Frequency range of validity [GHz].
    a, b : float
        Real relative permittivity law coefficients [-].
    c, d : float
        Conductivity law coefficients (``c`` in [S/m], ``d`` [-]).
    """

    f_min_ghz: float
    f_max_ghz: float
    a: float
    b: float
    c: float
    d: float

    def covers(self, f_ghz: float) -> bool:
        return self.f_min_ghz <= f_ghz <= self.f_max_ghz

    def log_distance(self, f_ghz: float) -> float:
        """How far ``f_ghz`` lies outside the row's range, in decades (0 inside)."""
        if self.covers(f_ghz):
            return 0.0
        edge = self.f_min_ghz if f_ghz < self.f_min_ghz else self.f_max_ghz
        return abs(math.log10(f_ghz / edge))


@dataclasses.dataclass(frozen=True)
class Material:
    """A named material with one or more frequency rows and a citation."""

    name: str
    rows: tuple[MaterialRow, ...]
    source: str

    @property
    def frequency_range_ghz(self) -> tuple[float, float]:
        """Union hull of the rows' ranges [GHz]."""
        return (min(r.f_min_ghz for r in self.rows), max(r.f_max_ghz for r in self.rows))


def _tan_delta_row(
    eps_r: float, tan_delta: float, f_min_ghz: float, f_max_ghz: float
) -> MaterialRow:
    """Row for a material given as (eps', tan delta): sigma = 2 pi f eps0 eps' tan(delta).

    With f in GHz this is ``sigma = c * f`` with ``c = 2 pi 1e9 eps0 eps' tan(delta)`` [S/m].
    """
    c = 2.0 * math.pi * 1e9 * VACUUM_PERMITTIVITY_F_M * eps_r * tan_delta
    return MaterialRow(f_min_ghz, f_max_ghz, eps_r, 0.0, c, 1.0)


_ITU = "ITU-R P.2040-3 (2023), Table 3"

#: The material table: name -> :class:`Material`. Read-only.
MATERIALS: Mapping[str, Material] = MappingProxyType(
    {
        m.name: m
        for m in (
            # --- ITU-R P.2040-3, Table 3 -------------------------------------------------
            Material("vacuum", (MaterialRow(0.001, 100.0, 1.0, 0.0, 0.0, 0.0),), _ITU),
            Material("concrete", (MaterialRow(1.0, 100.0, 5.24, 0.0, 0.0462, 0.7822),), _ITU),
            Material("brick", (MaterialRow(1.0, 40.0, 3.91, 0.0, 0.0238, 0.16),), _ITU),
            Material("plasterboard", (MaterialRow(1.0, 100.0, 2.73, 0.0, 0.0085, 0.9395),), _ITU),
            Material("wood", (MaterialRow(0.001, 100.0, 1.99, 0.0, 0.0047, 1.0718),), _ITU),
            Material(
                "glass",
                (
                    MaterialRow(0.1, 100.0, 6.31, 0.0, 0.0036, 1.3394),
                    MaterialRow(220.0, 450.0, 5.79, 0.0, 0.0004, 1.658),
                ),
                _ITU,
            ),
            Material(
                "ceiling_board",
                (
                    MaterialRow(1.0, 100.0, 1.48, 0.0, 0.0011, 1.0750),
                    MaterialRow(220.0, 450.0, 1.52, 0.0, 0.0029, 1.029),
                ),
                _ITU,
            ),
            Material("chipboard", (MaterialRow(1.0, 100.0, 2.58, 0.0, 0.0217, 0.78),), _ITU),
            Material("plywood", (MaterialRow(1.0, 40.0, 2.71, 0.0, 0.33, 0.0),), _ITU),
            Material("marble", (MaterialRow(1.0, 60.0, 7.074, 0.0, 0.0055, 0.9262),), _ITU),
            Material("floorboard", (MaterialRow(50.0, 100.0, 3.66, 0.0, 0.0044, 1.3515),), _ITU),
            Material("metal", (MaterialRow(1.0, 100.0, 1.0, 0.0, 1e7, 0.0),), _ITU),
            Material("vinyl_tile", (MaterialRow(1.0, 40.0, 3.62, 0.0, 0.0051, 0.8422),), _ITU),
            Material("carpet_tile", (MaterialRow(1.0, 40.0, 2.08, 0.0, 0.0009, 0.82),), _ITU),
            Material("very_dry_ground", (MaterialRow(1.0, 10.0, 3.0, 0.0, 0.00015, 2.52),), _ITU),
            Material("medium_dry_ground", (MaterialRow(1.0, 10.0, 15.0, -0.1, 0.035, 1.63),), _ITU),
            Material("wet_ground", (MaterialRow(1.0, 10.0, 30.0, -0.4, 0.15, 1.30),), _ITU),
            # --- literature values for the paper's VLM classes without an ITU row ---------
            Material(
                "ceramic_tile",
                (_tan_delta_row(6.0, 0.03, 50.0, 100.0),),
                "glazed ceramic wall/floor tile, eps'~6, tan(delta)~0.03 at 60 GHz: "
                "Sato et al., IEEE Trans. Antennas Propag. 45(12), 1997 (60 GHz interior "
                "materials); representative value, +-20 %",
            ),
            Material(
                "plastic",
                (_tan_delta_row(2.6, 0.008, 50.0, 300.0),),
                "ABS/PVC class plastics, eps'~2.6, tan(delta)~0.008 at mm-wave: Lamb, "
                "Int. J. Infrared Millim. Waves 17(12), 1996 (mm-wave materials compilation)",
            ),
            Material(
                "fabric",
                (_tan_delta_row(1.6, 0.02, 1.0, 100.0),),
                "cotton/polyester textiles, eps' 1.4-1.9: Sankaralingam & Gupta, IEEE Trans. "
                "Instrum. Meas. 59(12), 2010; tan(delta) ~0.02 assumed",
            ),
            Material(
                "unknown",
                (_tan_delta_row(3.0, 0.05, 0.001, 1000.0),),
                "sim2radar default for unlabelled surfaces: eps'=3.0 (between wood 1.99 and "
                "concrete 5.24 of ITU-R P.2040-3 Table 3), tan(delta)=0.05 (moderately lossy)",
            ),
        )
    }
)

_ALIASES = {
    "ceilingboard": "ceiling_board",
    "ceramic": "ceramic_tile",
    "tile": "ceramic_tile",
    "steel": "metal",
    "aluminium": "metal",
    "aluminum": "metal",
    "drywall": "plasterboard",
    "gypsum": "plasterboard",
    "air": "vacuum",
}

_WARNED: set[tuple[str, float]] = set()


def normalize_material_name(name: str) -> str:
    """Lower-case, strip, spaces/hyphens -> underscores, and resolve aliases."""
    key = str(name).strip().lower().replace("-", "_").replace(" ", "_")
    return _ALIASES.get(key, key)


def material_names() -> list[str]:
    """Known material names, sorted."""
    return sorted(MATERIALS)


def get_material(name: str) -> Material:
    """Look up a material by (normalised) name.

    Raises
    ------
    UnknownMaterialError
        Listing the known names.
    """
    key = normalize_material_name(name)
    try:
        return MATERIALS[key]
    except KeyError:
        raise UnknownMaterialError(
            f"unknown material {name!r}; known materials: {', '.join(material_names())}. "
            "Map the surface to one of these (or 'unknown' for the documented default)."
        ) from None


def _row_for(material: Material, f_ghz: float) -> MaterialRow:
    """The row covering ``f_ghz``; else the nearest one (in decades) with a warning."""
    for row in material.rows:
        if row.covers(f_ghz):
            return row
    row = min(material.rows, key=lambda r: r.log_distance(f_ghz))
    key = (material.name, row.f_min_ghz)
    if key not in _WARNED:
        _WARNED.add(key)
        warnings.warn(
            f"material {material.name!r}: {f_ghz:g} GHz lies outside its table range "
            f"[{row.f_min_ghz:g}, {row.f_max_ghz:g}] GHz ({material.source}); "
            "extrapolating the power laws eps'=a f^b, sigma=c f^d",
            MaterialFrequencyWarning,
            stacklevel=3,
        )
    return row


def material_parameters(material: str, frequency_hz: float) -> tuple[float, float]:
    """Real relative permittivity and conductivity of ``material`` at ``frequency_hz``.

    Parameters
    ----------
    material : str
        A name from :func:`material_names` (case-insensitive).
    frequency_hz : float
        Frequency [Hz], > 0.

    Returns
    -------
    eps_r : float
        Real part of the relative permittivity [-] (ITU-R P.2040-3 §2.1.4: a f^b).
    sigma_s_m : float
        Conductivity [S/m] (ITU-R P.2040-3 §2.1.4: c f^d).
    """
    f = float(frequency_hz)
    if not math.isfinite(f) or f <= 0:
        raise ValueError(f"frequency_hz must be a positive finite number, got {frequency_hz!r}")
    f_ghz = f / 1e9
    row = _row_for(get_material(material), f_ghz)
    eps_r = row.a * f_ghz**row.b  # ITU-R P.2040-3 §2.1.4, eps' = a f^b
    sigma = row.c * f_ghz**row.d  # ITU-R P.2040-3 §2.1.4, sigma = c f^d
    return float(eps_r), float(sigma)


def complex_permittivity(material: str, frequency_hz: float) -> complex:
    """Complex relative permittivity ``eta = eps' - j sigma / (omega eps0)``.

    ITU-R P.2040-3, eq. (9b) (``eps'' = 17.98 sigma / f_GHz``), with ``eps'`` and ``sigma``
    from the §2.1.4 power laws and Table 3.

    Parameters
    ----------
    material : str
        Material name (see :func:`material_names`).
    frequency_hz : float
        Frequency [Hz].

    Returns
    -------
    complex
        eta [-], with a non-positive imaginary part (e^{+j omega t} convention).
    """
    eps_r, sigma = material_parameters(material, frequency_hz)
    omega = 2.0 * math.pi * float(frequency_hz)
    return complex(eps_r, -sigma / (omega * VACUUM_PERMITTIVITY_F_M))
