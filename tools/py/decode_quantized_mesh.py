"""Decode every {z}/{x}/{y}.terrain under a folder with the quantized-mesh-tile
package (PyPI, independent of Relevo) and print one JSON line a tile: its
vertices as longitude, latitude and height, its triangles, its edge lists
and the extensions it read. Exit 1 when a tile does not decode."""

import json
import pathlib
import sys

from quantized_mesh_tile.global_geodetic import GlobalGeodetic
from quantized_mesh_tile.terrain import TerrainTile


def main(root):
    geodetic = GlobalGeodetic(True)
    failed = False
    for path in sorted(pathlib.Path(root).glob("*/*/*.terrain")):
        z, x, y = int(path.parts[-3]), int(path.parts[-2]), int(path.stem)
        west, south, east, north = geodetic.TileBounds(x, y, z)
        tile = TerrainTile(west=west, south=south, east=east, north=north)
        try:
            tile.fromFile(str(path), hasLighting=True, hasWatermask=True)
        except Exception as e:  # noqa: BLE001 - any failure is the finding
            print(f"{path}: {e}", file=sys.stderr)
            failed = True
            continue
        print(json.dumps({
            "z": z, "x": x, "y": y,
            "bounds": [west, south, east, north],
            "vertices": tile.getVerticesCoordinates(),
            "triangles": list(tile.indices),
            "edges": [list(tile.westI), list(tile.southI), list(tile.eastI), list(tile.northI)],
            "normals": len(tile.vLight),
            "watermask_rows": len(tile.watermask),
        }))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
