"""Optional lanelet2 .osm maps of the INTERACTION scenarios: lane lines to draw under plots.

The maps store nodes in latitude/longitude. As in the dataset's devkit, they are projected
with a UTM projector at origin (0, 0): x, y = utm(lat, lon) - utm(0, 0) in the UTM zone of
the origin (zone 31, central meridian 3 deg E), computed by pyproj. The parser uses only the
standard-library XML reader.
"""

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyproj


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


class OriginProjector:
    """lat/lon <-> local x/y [m] relative to a UTM projection of the origin (default 0, 0)."""

    def __init__(self, lat0_deg: float = 0.0, lon0_deg: float = 0.0):
        self.zone = utm_zone(lon0_deg)
        self._utm = pyproj.Proj(proj="utm", zone=self.zone, ellps="WGS84", datum="WGS84")
        self.x0, self.y0 = self._utm(lon0_deg, lat0_deg)

    def to_xy(self, lat_deg, lon_deg) -> np.ndarray:
        """[K, 2] local metres of latitude/longitude arrays."""
        east, north = self._utm(np.asarray(lon_deg, float), np.asarray(lat_deg, float))
        return np.stack([np.asarray(east) - self.x0, np.asarray(north) - self.y0], axis=-1)

    def to_latlon(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lat, lon) degrees of local points [K, 2] (for writing generated maps)."""
        xy = np.asarray(xy, dtype=np.float64)
        lon, lat = self._utm(xy[:, 0] + self.x0, xy[:, 1] + self.y0, inverse=True)
        return np.asarray(lat), np.asarray(lon)


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
