// Decode every {z}/{x}/{y}.terrain under a folder with HERE's
// @here/quantized-mesh-decoder (independent of Relevo) and print one JSON
// line a tile: its header, its vertices (u, v, height quantized), triangles,
// edge lists and extensions. Exit 1 when a tile does not decode.
import { readFileSync, readdirSync, statSync } from "node:fs";
import { join } from "node:path";
import decoder from "@here/quantized-mesh-decoder";

// The package is CommonJS with its function on `default`.
const decode = decoder.default ?? decoder;

const root = process.argv[2];
let failed = false;
for (const z of readdirSync(root).filter((d) => /^\d+$/.test(d))) {
  for (const x of readdirSync(join(root, z))) {
    for (const file of readdirSync(join(root, z, x))) {
      const path = join(root, z, x, file);
      const bytes = readFileSync(path);
      const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
      try {
        const tile = decode(buffer);
        const ext = tile.extensions;
        console.log(JSON.stringify({
          z: +z, x: +x, y: +file.replace(".terrain", ""),
          header: tile.header,
          vertices: Array.from(tile.vertexData),
          triangles: Array.from(tile.triangleIndices),
          west: Array.from(tile.westIndices), south: Array.from(tile.southIndices),
          east: Array.from(tile.eastIndices), north: Array.from(tile.northIndices),
          normals: ext.vertexNormals ? ext.vertexNormals.length : 0,
          waterMaskBytes: ext.waterMask ? ext.waterMask.byteLength : 0,
          metadata: ext.metadata ?? null,
        }));
      } catch (e) {
        console.error(`${path}: ${e}`);
        failed = true;
      }
    }
  }
}
// Not process.exit: it would cut off output still in the pipe.
process.exitCode = failed ? 1 : 0;
