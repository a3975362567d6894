// Time @mapbox/martini on raw little-endian float32 grids:
//   node martini-bench.mjs RUNS FILE SIDE [FILE SIDE …]
// prints one JSON object per grid with the median createTile and getMesh(max_error 0..) times.
import { readFileSync } from "node:fs";
import Martini from "@mapbox/martini";

const runs = Number(process.argv[2]);
const median = (xs) => xs.sort((a, b) => a - b)[Math.floor(xs.length / 2)];
for (let k = 3; k < process.argv.length; k += 2) {
  const file = process.argv[k];
  const side = Number(process.argv[k + 1]);
  const bytes = readFileSync(file);
  const terrain = new Float32Array(bytes.buffer, bytes.byteOffset, side * side);
  const martini = new Martini(side);
  const create = [], mesh = [];
  let tile, triangles = 0;
  for (let r = 0; r < runs; r++) {
    let t = process.hrtime.bigint();
    tile = martini.createTile(terrain);
    create.push(Number(process.hrtime.bigint() - t) / 1e6);
    t = process.hrtime.bigint();
    triangles = tile.getMesh(1).triangles.length / 3;
    mesh.push(Number(process.hrtime.bigint() - t) / 1e6);
  }
  console.log(JSON.stringify({ side, create_ms: median(create), mesh_ms: median(mesh), mesh_triangles: triangles }));
}
