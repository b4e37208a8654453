// cesium_heights.mjs — CesiumJS itself (the npm package `cesium`, run in Node) as the client of
// clipmapd's Cesium terrain: it reads layer.json, fetches quantized-mesh tiles through
// CesiumTerrainProvider and decodes them; then it prints, for each requested point, the
// height Cesium interpolates from the mesh. test_http compares them with the daemon's heights.
// usage: CLIPMAP_NPM=DIR node cesium_heights.mjs BASE_URL A F LEVEL X Y LON,LAT [LON,LAT...]
//   DIR       where `make deps` installed the npm packages (DIR/node_modules/cesium)
//   BASE_URL  e.g. http://127.0.0.1:8080/cesium/earth; A, F the planet's ellipsoid;
//   X, Y      Cesium's tile address (Y from the north, as the geographic tiling scheme counts).
// Prints one line per point: "LON LAT HEIGHT", then "available L X Y yes|no" for the child.
// With CLIPMAP_NORMALS=1 it asks for vertex normals (requestVertexNormals: the octvertexnormals
// extension) and then prints, per point, "normal LON LAT E N U": the normal Cesium decoded
// (AttributeCompression.octDecode) at the mesh vertex nearest the point, in the point's
// east-north-up frame; it fails when the tile came without normals.
import { createRequire } from "node:module";

const Cesium = createRequire(`${process.env.CLIPMAP_NPM}/`)("cesium");

const [base, a, f, level, x, y, ...points] = process.argv.slice(2);
const A = Number(a), B = A * (1 - Number(f));
const ellipsoid = new Cesium.Ellipsoid(A, A, B);
const normals = process.env.CLIPMAP_NORMALS === "1";
const provider = await Cesium.CesiumTerrainProvider.fromUrl(base, { ellipsoid,
	requestVertexNormals: normals });
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
if (normals) {
	const enc = data._encodedNormals;
	if (!provider.hasVertexNormals || !enc) {
		console.error(`no vertex normals (layer.json lists them: ${provider.hasVertexNormals})`);
		process.exit(1);
	}
	const u = data._uValues, v = data._vValues;
	for (const p of points) {
		const [lon, lat] = p.split(",").map(Number);
		const lo = Cesium.Math.toRadians(lon), la = Cesium.Math.toRadians(lat);
		const pu = (lo - rect.west) / rect.width * 32767, pv = (la - rect.south) / rect.height * 32767;
		let best = 0, bd = Infinity;
		for (let i = 0; i < u.length; i++) {
			const d = (u[i] - pu) ** 2 + (v[i] - pv) ** 2;
			if (d < bd) {
				bd = d;
				best = i;
			}
		}
		const n = Cesium.AttributeCompression.octDecode(enc[2 * best], enc[2 * best + 1],
			new Cesium.Cartesian3());
		const so = Math.sin(lo), co = Math.cos(lo), sa = Math.sin(la), ca = Math.cos(la);
		const e = -so * n.x + co * n.y, nn = -sa * co * n.x - sa * so * n.y + ca * n.z;
		const up = ca * co * n.x + ca * so * n.y + sa * n.z;
		console.log(`normal ${lon} ${lat} ${e} ${nn} ${up}`);
	}
}
