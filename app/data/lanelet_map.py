"""Optional lanelet2 .osm maps of the INTERACTION scenarios: lane lines to draw under plots.

The maps store nodes in latitude/longitude. As in the dataset's devkit, they are projected
with a UTM projector at origin (0, 0): x, y = utm(lat, lon) - utm(0, 0) in the UTM zone of
the origin (zone 31, central meridian 3 deg E). pyproj is used when installed; otherwise
the same Transverse Mercator projection is computed with Krueger's series (WGS84, third
order in the third flattening: about a millimetre within 3000 km of the central meridian).
The parser uses only the standard-library XML reader.
"""

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

WGS84_A_M = 6378137.0
WGS84_F = 1 / 298.257223563
UTM_K0 = 0.9996
UTM_FALSE_EASTING_M = 500000.0


class MapError(ValueError):
    """A map file that cannot be read; the message names the file."""


@dataclass(frozen=True)
class LaneLine:
    """One way of the map: its type tag (line_thin, curbstone, virtual, ...) and points [K, 2] m."""

    kind: str
    subtype: str
    points: np.ndarray


def utm_zone(lon_deg: float) -> int:
    """The UTM zone number of a longitude."""
    return int(math.floor((lon_deg + 180.0) / 6.0)) + 1


def _series():
    n = WGS84_F / (2 - WGS84_F)
    big_a = WGS84_A_M / (1 + n) * (1 + n**2 / 4 + n**4 / 64)
    alpha = (n / 2 - 2 * n**2 / 3 + 5 * n**3 / 16,
             13 * n**2 / 48 - 3 * n**3 / 5,
             61 * n**3 / 240)
    beta = (n / 2 - 2 * n**2 / 3 + 37 * n**3 / 96,
            n**2 / 48 + n**3 / 15,
            17 * n**3 / 480)
    delta = (2 * n - 2 * n**2 / 3 - 2 * n**3,
             7 * n**2 / 3 - 8 * n**3 / 5,
             56 * n**3 / 15)
    return n, big_a, alpha, beta, delta


def tm_forward(lat_deg, lon_deg, lon0_deg: float):
    """Transverse Mercator (UTM scale, false easting) of lat/lon arrays -> (easting, northing) m."""
    n, big_a, alpha, _, _ = _series()
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64))
    dlon = np.radians(np.asarray(lon_deg, dtype=np.float64) - lon0_deg)
    c = 2 * math.sqrt(n) / (1 + n)
    t = np.sinh(np.arctanh(np.sin(lat)) - c * np.arctanh(c * np.sin(lat)))
    xi = np.arctan2(t, np.cos(dlon))
    eta = np.arctanh(np.sin(dlon) / np.sqrt(1 + t**2))
    east = eta + sum(a * np.cos(2 * j * xi) * np.sinh(2 * j * eta)
                     for j, a in enumerate(alpha, start=1))
    north = xi + sum(a * np.sin(2 * j * xi) * np.cosh(2 * j * eta)
                     for j, a in enumerate(alpha, start=1))
    return UTM_FALSE_EASTING_M + UTM_K0 * big_a * east, UTM_K0 * big_a * north


def tm_inverse(east_m, north_m, lon0_deg: float):
    """Inverse of `tm_forward` (northern hemisphere): (lat, lon) in degrees."""
    _, big_a, _, beta, delta = _series()
    xi = np.asarray(north_m, dtype=np.float64) / (UTM_K0 * big_a)
    eta = (np.asarray(east_m, dtype=np.float64) - UTM_FALSE_EASTING_M) / (UTM_K0 * big_a)
    xi_p = xi - sum(b * np.sin(2 * j * xi) * np.cosh(2 * j * eta)
                    for j, b in enumerate(beta, start=1))
    eta_p = eta - sum(b * np.cos(2 * j * xi) * np.sinh(2 * j * eta)
                      for j, b in enumerate(beta, start=1))
    chi = np.arcsin(np.sin(xi_p) / np.cosh(eta_p))
    lat = chi + sum(d * np.sin(2 * j * chi) for j, d in enumerate(delta, start=1))
    lon = lon0_deg + np.degrees(np.arctan2(np.sinh(eta_p), np.cos(xi_p)))
    return np.degrees(lat), lon


class OriginProjector:
    """lat/lon <-> local x/y [m] relative to a UTM projection of the origin (default 0, 0)."""

    def __init__(self, lat0_deg: float = 0.0, lon0_deg: float = 0.0, use_pyproj: bool = True):
        self.zone = utm_zone(lon0_deg)
        self.central_lon_deg = 6.0 * self.zone - 183.0
        self._pyproj = _pyproj_transformer(self.zone) if use_pyproj else None
        self.x0, self.y0 = self._forward(np.array([lat0_deg]), np.array([lon0_deg]))

    def _forward(self, lat, lon):
        if self._pyproj is not None:
            return self._pyproj(lon, lat)
        return tm_forward(lat, lon, self.central_lon_deg)

    def to_xy(self, lat_deg, lon_deg) -> np.ndarray:
        """[K, 2] local metres of latitude/longitude arrays."""
        east, north = self._forward(np.asarray(lat_deg, float), np.asarray(lon_deg, float))
        return np.stack([np.asarray(east) - self.x0, np.asarray(north) - self.y0], axis=-1)

    def to_latlon(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lat, lon) degrees of local points [K, 2] (series inverse, for writing test maps)."""
        xy = np.asarray(xy, dtype=np.float64)
        return tm_inverse(xy[:, 0] + self.x0, xy[:, 1] + self.y0, self.central_lon_deg)


def _pyproj_transformer(zone: int):
    try:
        import pyproj
    except ImportError:
        return None
    proj = pyproj.Proj(proj="utm", zone=zone, ellps="WGS84", datum="WGS84")
    return lambda lon, lat: proj(lon, lat)


def read_lanelet_map(path: Path, projector: OriginProjector | None = None) -> list[LaneLine]:
    """Every way of a lanelet2 .osm file as a projected polyline with its type/subtype tags."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as err:
        raise MapError(f"{path}: not a readable OSM XML map: {err}") from None
    projector = projector or OriginProjector()
    ids, lats, lons = [], [], []
    for node in root.iter("node"):
        try:
            ids.append(node.attrib["id"])
            lats.append(float(node.attrib["lat"]))
            lons.append(float(node.attrib["lon"]))
        except (KeyError, ValueError):
            raise MapError(f"{path}: node {node.attrib.get('id', '?')} lacks a numeric "
                           f"lat/lon") from None
    xy = projector.to_xy(lats, lons) if ids else np.zeros((0, 2))
    where = {node_id: k for k, node_id in enumerate(ids)}
    lines = []
    for way in root.iter("way"):
        refs = [where[nd.attrib["ref"]] for nd in way.iter("nd") if nd.attrib.get("ref") in where]
        if len(refs) < 2:
            continue
        tags = {t.attrib.get("k"): t.attrib.get("v", "") for t in way.iter("tag")}
        lines.append(LaneLine(tags.get("type", ""), tags.get("subtype", ""), xy[refs]))
    return lines


LINE_STYLES = {"curbstone": ("#555555", 1.2, "-"), "line_thin": ("#888888", 0.8, "-"),
               "line_thick": ("#888888", 1.4, "-"), "virtual": ("#bbbbbb", 0.6, ":"),
               "stop_line": ("#aa4444", 1.0, "-")}


def draw_lane_lines(ax, lines: list[LaneLine]) -> None:
    """Draw map ways under a plot (dashed where the subtype says so)."""
    for line in lines:
        color, width, style = LINE_STYLES.get(line.kind, ("#aaaaaa", 0.6, "-"))
        if line.subtype == "dashed":
            style = "--"
        ax.plot(line.points[:, 0], line.points[:, 1], color=color, lw=width, ls=style,
                zorder=0)
