#!/usr/bin/env node
// Morphed, skinned normals of a glTF as three.js (r170) shades them, against normals recomputed
// from the morphed, skinned positions; and the positions a file shows with no animation playing.
//
// usage: node tools/node/normals_eval.mjs FILE.glb (--times t1,t2,... | --rest) [--mesh NAME] [--out result.json]
//
// --times: per time, per mesh, the angle (degrees) between three's normal and the one recomputed
//   from three's positions, mean / p95 / max over the vertices, and the same with the morph NORMAL
//   deltas left out; morph_*: before skinning (the blend shapes alone), else as shaded.
// --rest:  no animation is played: the mesh's default `weights` (GLTFLoader copies them into
//   morphTargetInfluences) on the joints' rest TRS; per mesh the world positions (flat).
//
// three.js has no CPU function for a shaded normal, so the shader chunks' maths is done here on
// three's own data (GLTFLoader's attributes and morph attributes, the mixer's influences, the
// skeleton's bone matrices):
//   morphnormal_vertex  n = NORMAL + Σ_k influence_k · morphNormal_k   (morphTargetsRelative)
//   skinnormal_vertex   n = (bindMatrixInverse · Σ_j w_j boneMatrix_j · bindMatrix) · (n, 0)
//   defaultnormal       n = normalMatrix(matrixWorld) · n, normalised
// Positions come from three's Mesh.getVertexPosition (morphs + skinning) as in skin_eval.mjs.
// The recomputed normals: three's BufferGeometry.computeVertexNormals (area-weighted) on the
// positions, seam-split copies merged first (BufferGeometryUtils.mergeVertices), so a seam does
// not show as a crease.
import fs from 'node:fs';
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { mergeVertices } from 'three/examples/jsm/utils/BufferGeometryUtils.js';

function usage(msg) {
	if (msg) console.error(`normals_eval: ${msg}`);
	console.error('usage: node normals_eval.mjs FILE.glb (--times t1,t2,... | --rest) [--mesh NAME] [--out result.json]');
	process.exit(2);
}

const opts = { file: null, times: null, rest: false, mesh: null, out: null };
{
	const a = process.argv.slice(2);
	for (let i = 0; i < a.length; i++) {
		const k = a[i];
		if (['--times', '--mesh', '--out'].includes(k)) {
			if (i + 1 >= a.length) usage(`${k} needs a value`);
			opts[k.slice(2)] = a[++i];
		} else if (k === '--rest') opts.rest = true;
		else if (k.startsWith('--')) usage(`unknown option ${k}`);
		else if (opts.file === null) opts.file = k;
		else usage(`extra argument ${k}`);
	}
	if (!opts.file) usage('no file');
	if (!opts.rest === !opts.times) usage('give --times or --rest');
	if (opts.times) {
		opts.times = opts.times.split(',').filter((s) => s.trim() !== '').map(Number);
		if (opts.times.length === 0 || opts.times.some((t) => !Number.isFinite(t))) usage('bad --times');
	}
}

globalThis.self ??= globalThis;
globalThis.window ??= globalThis;
const noTextures = () => ({ name: 'no_textures', loadTexture: () => Promise.resolve(new THREE.Texture()) });

const buf = fs.readFileSync(opts.file);
if (buf.subarray(0, 4).toString('latin1') !== 'glTF') usage('only .glb is read');
const loader = new GLTFLoader();
loader.pluginCallbacks.unshift(noTextures);
const gltf = await new Promise((resolve, reject) =>
	loader.parse(buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength), '', resolve, reject)).catch((e) => {
	console.error(`normals_eval: GLTFLoader failed on ${opts.file}: ${e?.stack ?? e}`);
	process.exit(1);
});
const scene = gltf.scene;

const meshes = [];
scene.traverse((o) => {
	if (o.isMesh && (opts.mesh === null || o.name === opts.mesh)) meshes.push(o);
});
if (meshes.length === 0) usage('no mesh');

let action = null;
let mixer = null;
if (opts.times) {
	const clip = gltf.animations[0];
	if (!clip) usage('file has no animation');
	mixer = new THREE.AnimationMixer(scene);
	action = mixer.clipAction(clip);
	action.setLoop(THREE.LoopOnce, 1);
	action.clampWhenFinished = true;
}

const v = new THREE.Vector3();

// World positions; `morphOnly`: the morphed points before skinning (three's Mesh method, which
// SkinnedMesh's overrides to add the skinning).
function positionsOf(obj, morphOnly = false) {
	const n = obj.geometry.attributes.position.count;
	const out = new Float64Array(3 * n);
	for (let i = 0; i < n; i++) {
		if (morphOnly) THREE.Mesh.prototype.getVertexPosition.call(obj, i, v);
		else obj.getVertexPosition(i, v);
		v.applyMatrix4(obj.matrixWorld);
		out[3 * i] = v.x; out[3 * i + 1] = v.y; out[3 * i + 2] = v.z;
	}
	return out;
}

// The shader's normal, world space, unit; `morphs`: add the morph NORMAL deltas; `skinned`:
// through the skin (else the morphed normal alone, as the blend shapes leave it).
function shadedNormals(obj, morphs, skinned = true) {
	const g = obj.geometry;
	const n = g.attributes.position.count;
	const base = g.attributes.normal;
	const targets = morphs ? (g.morphAttributes.normal ?? []) : [];
	const influences = obj.morphTargetInfluences ?? [];
	const normalMatrix = new THREE.Matrix3().getNormalMatrix(obj.matrixWorld);
	const skin = obj.isSkinnedMesh && skinned ? obj.skeleton : null;
	if (skin) skin.update(); // boneMatrices = bone.matrixWorld · boneInverse
	const m = new THREE.Matrix4();
	const bone = new THREE.Matrix4();
	const nv = new THREE.Vector3();
	const out = new Float64Array(3 * n);
	for (let i = 0; i < n; i++) {
		nv.fromBufferAttribute(base, i);
		for (let k = 0; k < targets.length; k++) {
			const w = influences[k];
			if (w !== 0) {
				nv.x += w * targets[k].getX(i); nv.y += w * targets[k].getY(i); nv.z += w * targets[k].getZ(i);
			}
		}
		if (skin) {
			m.set(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0);
			for (let s = 0; s < 4; s++) {
				const w = g.attributes.skinWeight.getComponent(i, s);
				if (w === 0) continue;
				bone.fromArray(skin.boneMatrices, 16 * g.attributes.skinIndex.getComponent(i, s));
				for (let e = 0; e < 16; e++) m.elements[e] += w * bone.elements[e];
			}
			m.premultiply(obj.bindMatrixInverse).multiply(obj.bindMatrix);
			nv.transformDirection(m); // (m · (n, 0)).xyz, normalised
		}
		nv.applyMatrix3(normalMatrix).normalize();
		out[3 * i] = nv.x; out[3 * i + 1] = nv.y; out[3 * i + 2] = nv.z;
	}
	return out;
}

// computeVertexNormals on the positions, seam copies merged, mapped back to the file's vertices.
function recomputedNormals(obj, positions) {
	const g = new THREE.BufferGeometry();
	g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(positions), 3));
	g.setIndex(obj.geometry.index.clone());
	const merged = mergeVertices(g, 1e-7);
	merged.computeVertexNormals();
	const map = new Int32Array(positions.length / 3);
	const a = g.index.array, b = merged.index.array;
	for (let c = 0; c < a.length; c++) map[a[c]] = b[c];
	const mn = merged.attributes.normal;
	const out = new Float64Array(positions.length);
	for (let i = 0; i < map.length; i++) {
		out[3 * i] = mn.getX(map[i]); out[3 * i + 1] = mn.getY(map[i]); out[3 * i + 2] = mn.getZ(map[i]);
	}
	return out;
}

function angles(p, q) {
	const n = p.length / 3;
	const out = new Float64Array(n);
	for (let i = 0; i < n; i++) {
		const d = p[3 * i] * q[3 * i] + p[3 * i + 1] * q[3 * i + 1] + p[3 * i + 2] * q[3 * i + 2];
		out[i] = Math.acos(Math.min(1, Math.max(-1, d))) * 180 / Math.PI;
	}
	return out;
}

function stats(a) {
	const s = Array.from(a).sort((x, y) => x - y);
	return { mean: s.reduce((x, y) => x + y, 0) / s.length, p95: s[Math.floor(0.95 * (s.length - 1))], max: s[s.length - 1] };
}

const result = { file: opts.file, three_version: THREE.REVISION, meshes: [] };
for (const obj of meshes) {
	result.meshes.push({ name: obj.name, vertex_count: obj.geometry.attributes.position.count, morph_normals: (obj.geometry.morphAttributes.normal ?? []).length, frames: [] });
}
if (opts.rest) {
	scene.updateMatrixWorld(true);
	meshes.forEach((obj, m) => {
		result.meshes[m].influences = Array.from(obj.morphTargetInfluences ?? []);
		const positions = positionsOf(obj);
		result.meshes[m].positions = Array.from(positions);
		result.meshes[m].degrees = stats(angles(shadedNormals(obj, true), recomputedNormals(obj, positions)));
	});
} else {
	for (const t of opts.times) {
		action.reset().play();
		mixer.setTime(t);
		scene.updateMatrixWorld(true);
		meshes.forEach((obj, m) => {
			const truth = recomputedNormals(obj, positionsOf(obj));
			const morphed = recomputedNormals(obj, positionsOf(obj, true));
			result.meshes[m].frames.push({
				time: t,
				// The blend shapes alone: morphed normals vs the morphed points' normals.
				morph_degrees: stats(angles(shadedNormals(obj, true, false), morphed)),
				morph_degrees_without_deltas: stats(angles(shadedNormals(obj, false, false), morphed)),
				// As shaded: then skinned (linear blend skinning of normals, as every engine does).
				degrees: stats(angles(shadedNormals(obj, true), truth)),
				degrees_without_deltas: stats(angles(shadedNormals(obj, false), truth)),
			});
		});
	}
}
const text = JSON.stringify(result);
if (opts.out) fs.writeFileSync(opts.out, text);
else process.stdout.write(text + '\n');
