// cesium_heights.mjs — CesiumJS itself (the npm package `cesium`, run in Node) as the client of
// clipmapd's Cesium terrain: it reads layer.json, fetches quantized-mesh tiles through
// CesiumTerrainProvider and decodes them; then it prints, for each requested point, the
// height Cesium interpolates from the mesh. test_http compares them with the daemon's heights.
// usage: CLIPMAP_NPM=DIR node cesium_heights.mjs BASE_URL A F LEVEL X Y LON,LAT [LON,LAT...]
//   DIR       where `make deps` installed the npm packages (DIR/node_modules/cesium)
//   BASE_URL  e.g. http://127.0.0.1:8080/cesium/earth; A, F the planet's ellipsoid;
//   X, Y      Cesium's tile address (Y from the north, as the geographic tiling scheme counts).
// Prints one line per point: "LON LAT HEIGHT", then "available L X Y yes|no" for the child.
import { createRequire } from "node:module";

const Cesium = createRequire(`${process.env.CLIPMAP_NPM}/`)("cesium");

const [base, a, f, level, x, y, ...points] = process.argv.slice(2);
const A = Number(a), B = A * (1 - Number(f));
const ellipsoid = new Cesium.Ellipsoid(A, A, B);
const provider = await Cesium.CesiumTerrainProvider.fromUrl(base, { ellipsoid });
const L = Number(level), X = Number(x), Y = Number(y);
const data = await provider.requestTileGeometry(X, Y, L);
if (!data) {
	console.error("no tile geometry");
	process.exit(1);
}
const rect = provider.tilingScheme.tileXYToRectangle(X, Y, L);
for (const p of points) {
	const [lon, lat] = p.split(",").map(Number);
	const h = data.interpolateHeight(rect, Cesium.Math.toRadians(lon), Cesium.Math.toRadians(lat));
	console.log(`${lon} ${lat} ${h}`);
}
console.log(`available ${L + 1} ${2 * X} ${2 * Y} ${provider.getTileDataAvailable(2 * X, 2 * Y, L + 1) ? "yes" : "no"}`);
