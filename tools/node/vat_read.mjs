#!/usr/bin/env node
// Reads a garmentbake vertex animation texture (VAT) with readers we did not write, rebuilds
// every frame's positions from the published layout alone, and compares them with a PC2.
//
// usage: node tools/node/vat_read.mjs NAME.vat.json CACHE.pc2 [--out result.json]
//
// The layout (docs/caches.md, "Vertex animation textures"): the sidecar JSON gives the frame
// count, rate, texture size and per-axis bounds; the glb (three.js GLTFLoader) gives each
// vertex's rest POSITION and its TEXCOORD_1 = ((column + 0.5) / width, 0.5 / height); texel
// (column, row) with row = frame from the image's top is `bounds_min + texel * (bounds_max -
// bounds_min)` added to the rest position; normals `2 * texel - 1`.
// Textures: `.exr` by three.js' EXRLoader (FloatType; it hands back the file's top line as its
// LAST row, the GL convention, so row r of the file is its row height-1-r), `.png` by pngjs
// (16-bit samples kept, `skipRescale`; RGBA out, row 0 the top).
// The PC2 (reference, read plainly): 32-byte header, then float32 x, y, z per point per frame.
// Which PC2 point a glb vertex is: the mesh's extras.sourceVertex when the glb was split at UV
// seams, else its own index; so a wrong column in TEXCOORD_1 shows as an error.
//
// Prints (and writes with --out) {frames, vertices, width, height, fps, max_error, mean_error,
// max_error_frame, normal_length_error, texels_outside, units}: distances in the file's units; the normals' length
// off 1 (their directions are checked against the positions in Rust).
import fs from 'node:fs';
import path from 'node:path';
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { EXRLoader } from 'three/examples/jsm/loaders/EXRLoader.js';
import { PNG } from 'pngjs';

function usage(msg) {
	if (msg) console.error(`vat_read: ${msg}`);
	console.error('usage: node vat_read.mjs NAME.vat.json CACHE.pc2 [--out result.json]');
	process.exit(2);
}

const args = process.argv.slice(2);
let out = null;
const files = [];
for (let i = 0; i < args.length; i++) {
	if (args[i] === '--out') out = args[++i];
	else files.push(args[i]);
}
if (files.length !== 2) usage('give the sidecar and a PC2');
const [sidecarPath, pc2Path] = files;
const dir = path.dirname(sidecarPath);
const side = JSON.parse(fs.readFileSync(sidecarPath, 'utf8'));

globalThis.self ??= globalThis;
globalThis.window ??= globalThis;

function arrayBuffer(file) {
	const b = fs.readFileSync(file);
	return b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength);
}

// A texture as {width, height, texel(col, row) -> [r, g, b] in 0..1, row 0 = the file's top}.
function readTexture(file) {
	if (file.toLowerCase().endsWith('.exr')) {
		const t = new EXRLoader().setDataType(THREE.FloatType).parse(arrayBuffer(file));
		const ch = t.data.length / (t.width * t.height);
		return {
			width: t.width,
			height: t.height,
			texel: (c, r) => {
				const o = ((t.height - 1 - r) * t.width + c) * ch;
				return [t.data[o], t.data[o + 1], t.data[o + 2]];
			},
		};
	}
	const png = PNG.sync.read(fs.readFileSync(file), { skipRescale: true });
	if (png.depth !== 16) usage(`${file}: ${png.depth}-bit PNG, expected 16`);
	return {
		width: png.width,
		height: png.height,
		texel: (c, r) => {
			const o = (r * png.width + c) * 4;
			return [png.data[o] / 65535, png.data[o + 1] / 65535, png.data[o + 2] / 65535];
		},
	};
}

const positions = readTexture(path.join(dir, side.positions));
const normals = readTexture(path.join(dir, side.normals));
if (positions.width !== side.width || positions.height !== side.height) {
	usage(`texture ${positions.width}x${positions.height}, the sidecar says ${side.width}x${side.height}`);
}

const loader = new GLTFLoader();
const gltf = await new Promise((res, rej) => loader.parse(arrayBuffer(path.join(dir, side.mesh)), '', res, rej));
let mesh = null;
gltf.scene.traverse((o) => { if (o.isMesh && !mesh) mesh = o; });
if (!mesh) usage('the glb has no mesh');
const g = mesh.geometry;
const rest = g.attributes.position;
const uv1 = g.attributes.uv1;
if (!uv1) usage('the glb has no TEXCOORD_1');
const source = mesh.userData.sourceVertex ?? null;

const pc2 = fs.readFileSync(pc2Path);
if (pc2.subarray(0, 11).toString('latin1') !== 'POINTCACHE2') usage(`${pc2Path}: not a PC2`);
const points = pc2.readInt32LE(16);
const samples = pc2.readInt32LE(28);
if (samples !== side.frame_count) usage(`the PC2 has ${samples} frames, the VAT ${side.frame_count}`);
const pc2At = (f, p) => [0, 1, 2].map((a) => pc2.readFloatLE(32 + ((f * points + p) * 3 + a) * 4));

const lo = side.bounds_min;
const hi = side.bounds_max;
let worst = 0;
let worstFrame = 0;
let sum = 0;
let count = 0;
let normalWorst = 0;
let outside = 0;
for (let k = 0; k < rest.count; k++) {
	const col = Math.round(uv1.getX(k) * side.width - 0.5);
	const row0 = Math.round(uv1.getY(k) * side.height - 0.5);
	const p = source ? source[k] : k;
	for (let f = 0; f < side.frame_count; f++) {
		if (col < 0 || col >= side.width || row0 + f < 0 || row0 + f >= side.height) {
			outside++; // a texel address off the texture: counted, not measured
			continue;
		}
		const t = positions.texel(col, row0 + f);
		const r = [rest.getX(k), rest.getY(k), rest.getZ(k)];
		const got = [0, 1, 2].map((a) => r[a] + lo[a] + t[a] * (hi[a] - lo[a]));
		const want = pc2At(f, p);
		const e = Math.hypot(got[0] - want[0], got[1] - want[1], got[2] - want[2]);
		sum += e;
		count++;
		if (e > worst) { worst = e; worstFrame = f; }
		const n = normals.texel(col, row0 + f).map((c) => 2 * c - 1);
		const len = Math.hypot(...n);
		if (len > 0.5) {
			// The normal must be unit (within quantisation); its direction is checked by Rust.
			normalWorst = Math.max(normalWorst, Math.abs(len - 1));
		}
	}
}
const result = {
	frames: side.frame_count,
	vertices: rest.count,
	width: positions.width,
	height: positions.height,
	fps: side.fps,
	max_error: worst,
	mean_error: count ? sum / count : null,
	max_error_frame: worstFrame,
	normal_length_error: normalWorst,
	texels_outside: outside,
	units: side.units,
};
const text = JSON.stringify(result);
if (out) fs.writeFileSync(out, text);
console.log(text);
