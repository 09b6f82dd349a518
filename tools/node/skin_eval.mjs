#!/usr/bin/env node
// Evaluate an animated skinned/morphed glTF with three.js (an independent
// reader) in plain Node, and dump world-space vertex positions per time.
//
// usage: node tools/node/skin_eval.mjs FILE.glb --times t1,t2,... \
//            [--animation NAME|INDEX] [--mesh NAME] [--out result.json]
//
// Output JSON (stdout, or --out file):
//   { file, three_version, animation, animation_index, duration,
//     tracks: [{name, interpolation, keys}],
//     meshes: [{ name, type, node_name, gltf_node, gltf_mesh, gltf_primitive,
//                vertex_count, morph_target_names,
//                frames: [{ time, morph_influences, positions: [x0,y0,z0,...] }] }] }
// Positions are float64 as three computes them on the CPU (JSON keeps full
// precision), in glTF world space (Y-up).
//
// How positions are computed (three r170, matches its skinning/morph shaders):
//   Mesh.getVertexPosition(i, v)        base + sum(influence_k * morphDelta_k)
//                                       (GLTFLoader sets morphTargetsRelative)
//   SkinnedMesh.getVertexPosition(i, v) the above, then applyBoneTransform:
//       v = bindMatrixInverse * sum_j w_j * (bone_j.matrixWorld * boneInverse_j) * bindMatrix * v
//   then v.applyMatrix4(mesh.matrixWorld)  (the shader's modelMatrix).
//   GLTFLoader binds with bindMatrix = identity and bindMode 'attached'
//   (bindMatrixInverse = matrixWorld^-1), so the result is exactly the glTF
//   rule  sum_j w_j * jointWorld_j * IBM_j * v  (skinned mesh node transform ignored).
import fs from 'node:fs';
import path from 'node:path';
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';

// ------------------------------------------------------------------ args
function usage(msg) {
	if (msg) console.error(`skin_eval: ${msg}`);
	console.error('usage: node skin_eval.mjs FILE.glb|FILE.gltf --times t1,t2,... [--animation NAME|INDEX] [--mesh NAME] [--out result.json] [--pc2 REF.pc2 [--pc2-map MAP.json]]');
	process.exit(2);
}

const opts = { times: null, animation: null, mesh: null, out: null, file: null, pc2: null, 'pc2-map': null };
{
	const a = process.argv.slice(2);
	for (let i = 0; i < a.length; i++) {
		const k = a[i];
		if (['--times', '--animation', '--mesh', '--out', '--pc2', '--pc2-map'].includes(k)) {
			if (i + 1 >= a.length) usage(`${k} needs a value`);
			opts[k.slice(2)] = a[++i];
		} else if (k.startsWith('--')) usage(`unknown option ${k}`);
		else if (opts.file === null) opts.file = k;
		else usage(`extra argument ${k}`);
	}
	if (!opts.file) usage('no file');
	if (!opts.times) usage('--times is required');
	opts.times = opts.times.split(',').filter((s) => s.trim() !== '').map(Number);
	if (opts.times.length === 0 || opts.times.some((t) => !Number.isFinite(t))) usage('bad --times');
}

// ------------------------------------------------------------------ Node polyfills
// GLTFLoader only touches browser globals for images. Node 20 has fetch,
// Blob, URL, TextDecoder; `self` is referenced by loadImageSource.
globalThis.self ??= globalThis;
globalThis.window ??= globalThis;
// FileLoader (used for the data: URIs of .gltf buffers) reports progress
// with ProgressEvent, which Node lacks.
globalThis.ProgressEvent ??= class ProgressEvent extends Event {
	constructor(type, init = {}) {
		super(type);
		this.lengthComputable = !!init.lengthComputable;
		this.loaded = init.loaded ?? 0;
		this.total = init.total ?? 0;
	}
};

// Textures never change positions, and image decoding needs a DOM/canvas.
// This plugin runs before every other plugin and the parser's own
// loadTexture, and hands back an empty Texture for every glTF texture.
function noTextures(parser) {
	return { name: 'garmentbake_no_textures', loadTexture: () => Promise.resolve(new THREE.Texture()) };
}

// ------------------------------------------------------------------ load
function loadInput(file) {
	const buf = fs.readFileSync(file);
	if (buf.subarray(0, 4).toString('latin1') === 'glTF') {
		return buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength); // own ArrayBuffer
	}
	// .gltf: Node's fetch cannot read file:// URIs, so inline external
	// buffers as data: URIs (GLTFLoader fetches those fine).
	const json = JSON.parse(buf.toString('utf8'));
	for (const b of json.buffers ?? []) {
		if (b.uri && !b.uri.startsWith('data:')) {
			const bin = fs.readFileSync(path.resolve(path.dirname(file), decodeURIComponent(b.uri)));
			b.uri = `data:application/octet-stream;base64,${bin.toString('base64')}`;
		}
	}
	return JSON.stringify(json);
}

const loader = new GLTFLoader();
loader.pluginCallbacks.unshift(noTextures); // first, so it wins _invokeOne
const gltf = await new Promise((resolve, reject) => loader.parse(loadInput(opts.file), '', resolve, reject)).catch((e) => {
	console.error(`skin_eval: GLTFLoader failed on ${opts.file}: ${e?.stack ?? e}`);
	process.exit(1);
});
const scene = gltf.scene;
const assoc = gltf.parser.associations;

// ------------------------------------------------------------------ animation
let clip = null;
let clipIndex = null;
if (gltf.animations.length > 0) {
	if (opts.animation === null) clipIndex = 0;
	else if (/^\d+$/.test(opts.animation)) clipIndex = Number(opts.animation);
	else clipIndex = gltf.animations.findIndex((c) => c.name === opts.animation);
	clip = gltf.animations[clipIndex];
	if (!clip) usage(`animation ${opts.animation} not found (have: ${gltf.animations.map((c, i) => `${i}:${c.name}`).join(', ')})`);
} else if (opts.animation !== null) {
	usage('file has no animations');
}

const INTERP = { [THREE.InterpolateDiscrete]: 'STEP', [THREE.InterpolateLinear]: 'LINEAR', [THREE.InterpolateSmooth]: 'SMOOTH' };
const tracks = clip
	? clip.tracks.map((t) => ({
		name: t.name,
		// GLTFLoader gives CUBICSPLINE tracks a custom interpolant factory
		interpolation: t.createInterpolant?.isInterpolantFactoryMethodGLTFCubicSpline ? 'CUBICSPLINE' : (INTERP[t.getInterpolation()] ?? String(t.getInterpolation())),
		keys: t.times.length,
	}))
	: [];

const mixer = new THREE.AnimationMixer(scene);
const action = clip ? mixer.clipAction(clip) : null;
if (action) {
	// LoopOnce + clamp: t == duration must give the LAST key. The default
	// LoopRepeat wraps t == duration back to t = 0.
	action.setLoop(THREE.LoopOnce, 1);
	action.clampWhenFinished = true;
}
const duration = clip ? clip.duration : 0;
const EPS = 1e-6;
for (const t of opts.times) {
	if (t < -EPS || t > duration + EPS) usage(`time ${t} outside clip [0, ${duration}]`);
}

// ------------------------------------------------------------------ meshes
function glTFNodeOf(obj) {
	// a single-primitive mesh IS its node object; multi-primitive meshes are
	// children of a Group that carries the node association
	for (let o = obj; o; o = o.parent) {
		const a = assoc.get(o);
		if (a && a.nodes !== undefined) return { obj: o, index: a.nodes };
	}
	return { obj: null, index: null };
}

const meshes = [];
scene.traverse((o) => {
	if (!o.isMesh) return;
	const a = assoc.get(o) ?? {};
	const node = glTFNodeOf(o);
	const nodeName = node.obj ? (node.obj.userData.name ?? node.obj.name) : null;
	if (opts.mesh !== null && ![o.name, nodeName, node.obj?.name].includes(opts.mesh)) return;
	meshes.push({
		obj: o,
		rec: {
			name: o.name,
			type: o.isSkinnedMesh ? 'SkinnedMesh' : 'Mesh',
			node_name: nodeName,
			gltf_node: node.index,
			gltf_mesh: a.meshes ?? null,
			gltf_primitive: a.primitives ?? null,
			vertex_count: o.geometry.attributes.position.count,
			morph_target_names: o.morphTargetDictionary
				? Object.entries(o.morphTargetDictionary).sort((x, y) => x[1] - y[1]).map((e) => e[0])
				: [],
			frames: [],
		},
	});
});
if (meshes.length === 0) usage(opts.mesh !== null ? `no mesh named ${opts.mesh}` : 'no meshes in file');

// ------------------------------------------------------------------ reference
// --pc2: compare with a point cache instead of dumping positions (long clips stay small):
// the i-th time is compared with the cache's i-th sample; --pc2-map gives, per file vertex, the
// cache vertex it came from (vertices split at UV seams).
let reference = null;
if (opts.pc2) {
	const b = fs.readFileSync(opts.pc2);
	if (b.toString('latin1', 0, 11) !== 'POINTCACHE2') usage(`${opts.pc2}: not a PC2 file`);
	const points = b.readInt32LE(16);
	const samples = b.readInt32LE(28);
	const data = new Float32Array(b.buffer.slice(b.byteOffset + 32, b.byteOffset + 32 + samples * points * 12));
	const map = opts['pc2-map'] ? JSON.parse(fs.readFileSync(opts['pc2-map'], 'utf8')) : null;
	if (opts.times.length > samples) usage(`${opts.pc2} has ${samples} samples, ${opts.times.length} times asked`);
	reference = { points, data, map };
}

// ------------------------------------------------------------------ evaluate
const t0 = performance.now();
const v = new THREE.Vector3();
for (const t of opts.times) {
	const tc = Math.min(Math.max(t, 0), duration);
	if (action) {
		// reset() clears the paused/finished state left by a previous clamp,
		// then setTime() evaluates every track at exactly tc.
		action.reset().play();
		mixer.setTime(tc);
	}
	scene.updateMatrixWorld(true); // bones + meshes (updates bindMatrixInverse too)
	for (const { obj, rec } of meshes) {
		const n = rec.vertex_count;
		const pos = new Array(3 * n);
		for (let i = 0; i < n; i++) {
			obj.getVertexPosition(i, v); // morphs (+ skinning for SkinnedMesh)
			v.applyMatrix4(obj.matrixWorld); // modelMatrix
			pos[3 * i] = v.x;
			pos[3 * i + 1] = v.y;
			pos[3 * i + 2] = v.z;
		}
		if (reference) {
			const k = rec.frames.length;
			let max = 0, sum = 0;
			for (let i = 0; i < n; i++) {
				const r = reference.map ? reference.map[i] : i;
				const o = (k * reference.points + r) * 3;
				const d = Math.hypot(pos[3 * i] - reference.data[o], pos[3 * i + 1] - reference.data[o + 1], pos[3 * i + 2] - reference.data[o + 2]);
				max = Math.max(max, d);
				sum += d;
			}
			rec.frames.push({ time: t, max_error: max, mean_error: sum / n });
			rec.max_error = Math.max(rec.max_error ?? 0, max);
			continue;
		}
		rec.frames.push({
			time: t,
			morph_influences: obj.morphTargetInfluences ? Array.from(obj.morphTargetInfluences) : [],
			positions: pos,
		});
	}
}
const elapsed = performance.now() - t0;

const result = {
	file: opts.file,
	three_version: THREE.REVISION,
	animation: clip ? clip.name : null,
	animation_index: clipIndex,
	duration,
	tracks,
	eval_ms: Math.round(elapsed),
	meshes: meshes.map((m) => m.rec),
};
const text = JSON.stringify(result);
if (opts.out) {
	fs.writeFileSync(opts.out, text);
	console.error(`skin_eval: ${opts.file}: ${meshes.length} mesh(es), ${opts.times.length} time(s), ${Math.round(elapsed)} ms -> ${opts.out}`);
} else {
	process.stdout.write(text + '\n');
}
