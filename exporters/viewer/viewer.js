// garmentbake view: plays a baked glTF in the browser, with point caches on its garment mesh and
// per-vertex error colours against a reference cache. Data comes from the page's #gb-data block
// (written by exporters/src/viewer.rs); the state can be set from the URL hash (see page.html).
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';

const data = JSON.parse(document.getElementById('gb-data').textContent);
const params = new URLSearchParams(location.search);
for (const [k, v] of new URLSearchParams(location.hash.slice(1))) params.set(k, v);

// The colours of `garmentbake preview` (src/preview/mod.rs), so a page and a preview read alike.
const BACKGROUND = [238, 238, 238];
const BODY_GREY = [175, 175, 178];
const GARMENT_COLORS = [[70, 120, 210], [210, 90, 70], [80, 170, 100], [200, 160, 60]];
// Margin of the fixed views' framing: src/preview/framing.rs (MARGIN, MIN_EXTENT).
const MARGIN = 0.05;
const MIN_EXTENT = 1e-3;
// Unit vectors toward the camera of the fixed views: src/preview/framing.rs (View).
const H = Math.SQRT1_2;
const VIEWS = {
	front: [0, 0, 1],
	side: [1, 0, 0],
	back: [0, 0, -1],
	'three-quarter': [H, 0, H],
};

const $ = (id) => document.getElementById(id);
const srgb = (c) => new THREE.Color().setRGB(c[0] / 255, c[1] / 255, c[2] / 255, THREE.SRGBColorSpace);
const bytes = (b64) => Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
const floats = (b64) => new Float32Array(bytes(b64).buffer);

function say(text) {
	$('message').textContent = text;
	$('message').hidden = false;
}

// ------------------------------------------------------------------ scene
// Colours and shading straight in display values, as the preview computes them (no sRGB decode
// and re-encode, which would flatten the shading).
THREE.ColorManagement.enabled = false;
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
renderer.setPixelRatio(window.devicePixelRatio);
$('stage').appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = srgb(BACKGROUND);
// Ambient + a headlight, the preview's shading: src/preview/raster.rs AMBIENT, DIFFUSE (three's
// lights carry a factor of pi).
scene.add(new THREE.AmbientLight(0xffffff, 0.28 * Math.PI));
const headlight = new THREE.DirectionalLight(0xffffff, 0.72 * Math.PI);
scene.add(headlight, headlight.target);
const ortho = new THREE.OrthographicCamera(-1, 1, 1, -1, 0.01, 1000);
const perspective = new THREE.PerspectiveCamera(30, 1, 0.01, 1000);

const WHITE = new THREE.Color(1, 1, 1);
function material(color) {
	const m = new THREE.MeshLambertMaterial({ color: srgb(color), side: THREE.DoubleSide });
	m.userData.color = srgb(color); // restored when error colours go off
	return m;
}

// ------------------------------------------------------------------ state
const state = {
	clips: [],
	clip: -1,
	action: null,
	fps: data.fps || 30,
	frames: 1,
	time: 0,
	playing: false,
	view: 'turntable',
	azimuth: 0.6,
	elevation: 0.15,
	distance: 3,
	target: new THREE.Vector3(0, 1, 0),
};
let mixer = null;
let garment = null; // the glTF's garment mesh (skinned bake, or the caches' mesh)
let bodies = []; // every other mesh
const tracks = []; // { name, points, frames, data, mesh, checkbox }
let reference = null;
let vertexMap = null; // garment vertex -> cache point
let vat = null; // { mesh, row, columns, positions, normals, min, range, frames } when a VAT plays

function cachePoint(v) {
	return vertexMap ? vertexMap[v] : v;
}

// ------------------------------------------------------------------ load
function load() {
	const failed = (e) => say(`cannot read the glTF: ${e.message || e}`);
	const loaded = (gltf) => (data.vat ? loadVat(gltf) : start(gltf));
	if (data.glb === null) loaded({ scene: new THREE.Group(), animations: [] });
	else new GLTFLoader().parse(bytes(data.glb).buffer, '', loaded, failed);
}

// ------------------------------------------------------------------ vertex animation textures
// A VAT (exporters/src/vat.rs, docs/caches.md) plays as an engine plays it: its glb's mesh at
// rest, and a vertex shader that reads frame f's texel at TEXCOORD_1 + (0, f / height), adds
// bounds_min + texel * (bounds_max - bounds_min) to the rest position, and takes the normal
// 2 * texel - 1 from the normals texture. The texels are the files' (decoded by the binary), in
// float textures sampled at texel centres.
function loadVat(gltf) {
	const v = data.vat;
	new GLTFLoader().parse(bytes(v.glb).buffer, '', (own) => {
		let mesh = null;
		own.scene.traverse((o) => {
			if (o.isMesh && !mesh) mesh = o;
		});
		if (!mesh || !mesh.geometry.attributes.uv1) {
			say(`${v.name}: its glb has no mesh with a second UV set`);
			return;
		}
		// The glTF's own garment (the caches' mesh of an eval / rollout page) gives way to it.
		gltf.scene.traverse((o) => {
			if (o.isMesh && o.name === data.garment) o.visible = false;
		});
		const texture = (b64) => {
			const rgb = floats(b64);
			const rgba = new Float32Array(v.width * v.height * 4);
			for (let i = 0; i < v.width * v.height; i++) rgba.set(rgb.subarray(3 * i, 3 * i + 3), 4 * i);
			const t = new THREE.DataTexture(rgba, v.width, v.height, THREE.RGBAFormat, THREE.FloatType);
			t.minFilter = t.magFilter = THREE.NearestFilter;
			t.generateMipmaps = false;
			t.needsUpdate = true;
			return t;
		};
		const min = new THREE.Vector3(...v.boundsMin);
		const range = new THREE.Vector3(...v.boundsMax).sub(min);
		const uv1 = mesh.geometry.attributes.uv1;
		vat = {
			mesh,
			row: { value: 0 },
			columns: Uint32Array.from({ length: uv1.count }, (_, i) => Math.round(uv1.getX(i) * v.width - 0.5)),
			positions: floats(v.positions),
			frames: v.height,
			min,
			range,
		};
		mesh.geometry.setAttribute('vatUv', uv1);
		const m = material(GARMENT_COLORS[0]);
		const uniforms = {
			vatPositions: { value: texture(v.positions) },
			vatNormals: { value: texture(v.normals) },
			vatRow: vat.row,
			vatMin: { value: min },
			vatRange: { value: range },
		};
		m.onBeforeCompile = (shader) => {
			Object.assign(shader.uniforms, uniforms);
			shader.vertexShader =
				'uniform sampler2D vatPositions;\nuniform sampler2D vatNormals;\nuniform float vatRow;\nuniform vec3 vatMin;\nuniform vec3 vatRange;\nattribute vec2 vatUv;\n' +
				shader.vertexShader
					.replace(
						'#include <beginnormal_vertex>',
						'vec2 vatAt = vec2(vatUv.x, vatUv.y + vatRow);\nvec3 objectNormal = texture2D(vatNormals, vatAt).rgb * 2.0 - 1.0;',
					)
					.replace('#include <begin_vertex>', 'vec3 transformed = position + vatMin + texture2D(vatPositions, vatAt).rgb * vatRange;');
		};
		mesh.material = m;
		mesh.frustumCulled = false;
		mesh.name = 'garment';
		gltf.scene.add(mesh);
		data.garment = 'garment';
		data.garmentIsBake = true;
		if (!data.fps && gltf.animations.length === 0) data.fps = v.fps;
		start(gltf);
	}, (e) => say(`cannot read ${v.name}'s glb: ${e.message || e}`));
}

// World position of VAT vertex v at the shown row, as the shader computes it.
function vatVertex(v, out) {
	const f = Math.round(vat.row.value * vat.frames);
	const t = (f * data.vat.width + vat.columns[v]) * 3;
	const p = vat.positions;
	out.fromBufferAttribute(vat.mesh.geometry.attributes.position, v);
	out.x += vat.min.x + p[t] * vat.range.x;
	out.y += vat.min.y + p[t + 1] * vat.range.y;
	out.z += vat.min.z + p[t + 2] * vat.range.z;
	return out.applyMatrix4(vat.mesh.matrixWorld);
}

function start(gltf) {
	scene.add(gltf.scene);
	gltf.scene.traverse((o) => {
		if (!o.isMesh) return;
		// Skinned bounds are the rest pose's: never cull a posed garment.
		o.frustumCulled = false;
		if (vat && o !== vat.mesh && o.name === 'garment') return; // the caches' mesh, hidden
		if (!garment && (data.garment === null || o.name === data.garment)) garment = o;
		else bodies.push(o);
	});
	if (!garment) {
		say('this glTF has no mesh to show');
		return;
	}
	if (!vat) garment.material = material(GARMENT_COLORS[0]);
	garment.visible = data.garmentIsBake;
	for (const b of bodies) b.material = material(BODY_GREY);
	if (data.vertexMap) vertexMap = Uint32Array.from(data.vertexMap);
	addTracks();
	mixer = new THREE.AnimationMixer(gltf.scene);
	state.clips = gltf.animations;
	for (const [i, clip] of state.clips.entries()) $('clip').add(new Option(clip.name || `clip ${i}`, String(i)));
	if (state.clips.length === 0) {
		$('clip').disabled = true;
		say(`${data.title} has no animations: showing the rest pose`);
	}
	$('body').hidden = bodies.length === 0;
	wireUi();
	applyParams();
	pose();
	fitTurntable();
	draw();
	// Headless checks wait for this (tests/integration/view.rs).
	document.body.dataset.ready = '1';
	requestAnimationFrame(tick);
}

function addTracks() {
	const index = garment.geometry.index;
	const count = garment.geometry.attributes.position.count;
	for (const [i, t] of data.tracks.entries()) {
		const geometry = new THREE.BufferGeometry();
		geometry.setIndex(index);
		geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(count * 3), 3));
		geometry.setAttribute('color', new THREE.BufferAttribute(new Float32Array(count * 3).fill(1), 3));
		const color = GARMENT_COLORS[(i + 1) % GARMENT_COLORS.length];
		const mesh = new THREE.Mesh(geometry, material(color));
		mesh.frustumCulled = false;
		scene.add(mesh);
		const track = { ...t, data: floats(t.data), mesh };
		tracks.push(track);
		const label = document.createElement('label');
		label.innerHTML = `<input type="checkbox" checked> <span style="color:rgb(${color})">■</span> `;
		label.append(t.name);
		track.checkbox = label.querySelector('input');
		track.checkbox.addEventListener('change', draw);
		$('tracks').append(label);
	}
	if (data.garmentIsBake && tracks.length > 0) {
		const label = document.createElement('label');
		label.innerHTML = `<input type="checkbox" id="bake" checked> <span style="color:rgb(${GARMENT_COLORS[0]})">■</span> bake`;
		$('tracks').prepend(label);
		$('bake').addEventListener('change', draw);
	}
	// Side by side needs two garments: the bake and a cache, or two caches.
	$('layout-row').hidden = tracks.length + (data.garmentIsBake ? 1 : 0) < 2;
	if (data.referenceTrack !== null) {
		const t = tracks[data.referenceTrack];
		reference = { points: t.points, frames: t.frames, data: t.data };
	} else if (data.reference) {
		reference = { ...data.reference, data: floats(data.reference.data) };
	}
	if (reference) {
		$('error-row').hidden = false;
		$('legend').hidden = false;
		$('legend-max').textContent = `${data.errorScaleMm} mm`;
		drawLegendBar();
	}
}

// ------------------------------------------------------------------ time
function selectClip(i) {
	if (state.action) state.action.stop();
	state.clip = i;
	const clip = state.clips[i];
	state.action = mixer.clipAction(clip);
	state.action.play();
	// A clip's keys are one per frame: its rate is the key spacing.
	const keyed = clip.tracks.find((t) => t.times.length > 1);
	state.fps = data.fps || (keyed ? 1 / (keyed.times[1] - keyed.times[0]) : 30);
	state.frames = Math.round(clip.duration * state.fps) + 1;
	setupScrub();
}

function setupScrub() {
	if (state.clips.length === 0) {
		state.frames = Math.max(1, vat ? vat.frames : 1, ...tracks.map((t) => t.frames));
	}
	$('scrub').max = String(state.frames - 1);
}

function frameOf(time) {
	return Math.min(state.frames - 1, Math.max(0, Math.round(time * state.fps)));
}

function duration() {
	return (state.frames - 1) / state.fps;
}

// ------------------------------------------------------------------ pose the frame
function pose() {
	const frame = frameOf(state.time);
	if (state.action) {
		state.action.time = state.time;
		mixer.update(0);
	}
	scene.updateMatrixWorld(true);
	if (vat) vat.row.value = Math.min(frame, vat.frames - 1) / vat.frames;
	const showBake = data.garmentIsBake && (!$('bake') || $('bake').checked);
	garment.visible = showBake;
	const spacing = $('layout').value === 'side' ? sideSpacing() : 0;
	// The bake (with the body) stands at 0, the caches to its right; without a bake, the first
	// cache stands on the body.
	let slot = showBake ? 1 : 0;
	for (const t of tracks) {
		t.mesh.visible = t.checkbox.checked;
		if (!t.mesh.visible) continue;
		const f = Math.min(frame, t.frames - 1);
		const pos = t.mesh.geometry.attributes.position.array;
		for (let v = 0; v < pos.length / 3; v++) {
			const s = (f * t.points + cachePoint(v)) * 3;
			pos[3 * v] = t.data[s];
			pos[3 * v + 1] = t.data[s + 1];
			pos[3 * v + 2] = t.data[s + 2];
		}
		t.mesh.geometry.attributes.position.needsUpdate = true;
		t.mesh.geometry.computeVertexNormals();
		t.mesh.position.x = spacing * slot++;
		t.mesh.updateMatrixWorld(true);
	}
	for (const b of bodies) b.visible = $('body').checked;
	colourErrors(frame);
	const wire = $('wire').checked;
	for (const m of [garment, ...bodies, ...tracks.map((t) => t.mesh)]) m.material.wireframe = wire;
	$('clock').textContent = `frame ${frame} / ${state.frames - 1} · ${state.time.toFixed(3)} s`;
	$('scrub').value = String(frame);
}

// Garment width plus a gap: tracks stand beside the bake in the side-by-side layout.
function sideSpacing() {
	const box = new THREE.Box3().setFromObject(bodies.length > 0 && $('body').checked ? bodies[0] : garment);
	return (box.max.x - box.min.x) * 1.15;
}

// World position of vertex v of a mesh as the GPU draws it (morphs, then skinning, then the node).
function worldVertex(mesh, v, out) {
	if (vat && mesh === vat.mesh) return vatVertex(v, out);
	if (mesh.isSkinnedMesh || mesh.morphTargetInfluences) mesh.getVertexPosition(v, out);
	else out.fromBufferAttribute(mesh.geometry.attributes.position, v);
	return out.applyMatrix4(mesh.matrixWorld);
}

// ------------------------------------------------------------------ error colours
function colourErrors(frame) {
	const on = reference && $('error').checked;
	$('legend').hidden = !on;
	const shown = [];
	if (garment.visible) shown.push({ mesh: garment, own: (v, p) => worldVertex(garment, v, p) });
	for (const t of tracks) {
		if (!t.mesh.visible) continue;
		const pos = t.mesh.geometry.attributes.position;
		shown.push({ mesh: t.mesh, own: (v, p) => p.fromBufferAttribute(pos, v) });
	}
	let worst = 0;
	const p = new THREE.Vector3();
	const color = new THREE.Color();
	for (const s of shown) {
		const m = s.mesh.material;
		if (m.vertexColors !== on) m.needsUpdate = true;
		m.vertexColors = on;
		m.color.copy(on ? WHITE : m.userData.color);
		if (!on) continue;
		const geometry = s.mesh.geometry;
		const n = geometry.attributes.position.count;
		if (!geometry.attributes.color) geometry.setAttribute('color', new THREE.BufferAttribute(new Float32Array(n * 3), 3));
		const colors = geometry.attributes.color;
		const f = Math.min(frame, reference.frames - 1);
		for (let v = 0; v < n; v++) {
			s.own(v, p);
			const r = (f * reference.points + cachePoint(v)) * 3;
			const mm = 1000 * Math.hypot(p.x - reference.data[r], p.y - reference.data[r + 1], p.z - reference.data[r + 2]);
			worst = Math.max(worst, mm);
			ramp(mm / data.errorScaleMm, color);
			colors.setXYZ(v, color.r, color.g, color.b);
		}
		colors.needsUpdate = true;
	}
	if (on) $('legend-now').textContent = `max this frame ${worst.toFixed(2)} mm (frame ${Math.min(frame, reference.frames - 1)} of the reference)`;
}

// 0 → blue, 0.5 → yellow, 1 and above → red.
function ramp(x, out) {
	const t = Math.min(1, Math.max(0, x));
	const stops = [[40, 90, 200], [240, 220, 60], [210, 40, 40]];
	const k = t < 0.5 ? 0 : 1;
	const u = t < 0.5 ? t * 2 : (t - 0.5) * 2;
	const c = stops[k].map((a, i) => a + (stops[k + 1][i] - a) * u);
	return out.setRGB(c[0] / 255, c[1] / 255, c[2] / 255, THREE.SRGBColorSpace);
}

function drawLegendBar() {
	const canvas = $('legend-bar');
	const ctx = canvas.getContext('2d');
	const c = new THREE.Color();
	for (let x = 0; x < canvas.width; x++) {
		ramp(x / (canvas.width - 1), c);
		ctx.fillStyle = `#${c.getHexString(THREE.SRGBColorSpace)}`;
		ctx.fillRect(x, 0, 1, canvas.height);
	}
}

// ------------------------------------------------------------------ cameras
function visibleMeshes() {
	return [garment, ...bodies, ...tracks.map((t) => t.mesh)].filter((m) => m.visible);
}

// The fixed views frame like `garmentbake preview` (src/preview/framing.rs, Framing::fit): the
// bounds of every drawn vertex on the view plane, 5 % of the larger extent added on every side,
// scaled uniformly into the window and centred.
function frameFixed(toward) {
	const right = new THREE.Vector3(toward[2], 0, -toward[0]);
	const back = new THREE.Vector3(...toward);
	let [u0, v0, u1, v1] = [Infinity, Infinity, -Infinity, -Infinity];
	const p = new THREE.Vector3();
	for (const m of visibleMeshes()) {
		const n = m.geometry.attributes.position.count;
		for (let v = 0; v < n; v++) {
			worldVertex(m, v, p);
			const u = p.dot(right);
			u0 = Math.min(u0, u);
			u1 = Math.max(u1, u);
			v0 = Math.min(v0, p.y);
			v1 = Math.max(v1, p.y);
		}
	}
	if (!(u0 <= u1)) [u0, v0, u1, v1] = [-1, -1, 1, 1];
	const pad = MARGIN * Math.max(u1 - u0, v1 - v0, MIN_EXTENT);
	[u0, v0, u1, v1] = [u0 - pad, v0 - pad, u1 + pad, v1 + pad];
	const [w, h] = [window.innerWidth, window.innerHeight];
	const scale = Math.min(w / Math.max(u1 - u0, MIN_EXTENT), h / Math.max(v1 - v0, MIN_EXTENT));
	const [uc, vc] = [(u0 + u1) / 2, (v0 + v1) / 2];
	Object.assign(ortho, { left: -w / 2 / scale, right: w / 2 / scale, top: h / 2 / scale, bottom: -h / 2 / scale });
	ortho.updateProjectionMatrix();
	ortho.position.copy(right.clone().multiplyScalar(uc)).add(back.clone().multiplyScalar(100));
	ortho.position.y = vc;
	ortho.up.set(0, 1, 0);
	ortho.lookAt(ortho.position.clone().sub(back));
	return ortho;
}

// The turntable's pivot and distance: the drawn meshes of the first frame.
function fitTurntable() {
	const box = new THREE.Box3();
	for (const m of visibleMeshes()) box.expandByObject(m, true);
	if (box.isEmpty()) return;
	box.getCenter(state.target);
	const size = box.getSize(new THREE.Vector3());
	const fov = THREE.MathUtils.degToRad(perspective.fov);
	state.distance = (1.15 * Math.max(size.y, size.x / perspective.aspect)) / 2 / Math.tan(fov / 2) + size.z;
}

function turntable() {
	const { azimuth: a, elevation: e, distance: d, target } = state;
	perspective.aspect = window.innerWidth / window.innerHeight;
	perspective.updateProjectionMatrix();
	perspective.position.set(
		target.x + d * Math.cos(e) * Math.sin(a),
		target.y + d * Math.sin(e),
		target.z + d * Math.cos(e) * Math.cos(a),
	);
	perspective.lookAt(target);
	return perspective;
}

// ------------------------------------------------------------------ draw loop
function draw() {
	renderer.setSize(window.innerWidth, window.innerHeight);
	pose();
	const camera = state.view === 'turntable' ? turntable() : frameFixed(VIEWS[state.view]);
	// The headlight sits above and left of the camera, as in the preview.
	headlight.position.copy(camera.position).add(new THREE.Vector3(-0.35, 0.55, 0).applyQuaternion(camera.quaternion));
	headlight.target.position.copy(state.target);
	renderer.render(scene, camera);
}

let last = null;
function tick(now) {
	const dt = last === null ? 0 : (now - last) / 1000;
	last = now;
	let dirty = false;
	if (state.playing) {
		const d = duration();
		state.time = d > 0 ? (state.time + dt) % (d + 1 / state.fps) : 0;
		dirty = true;
	}
	if ($('spin').checked && state.view === 'turntable') {
		state.azimuth += dt * 0.6;
		dirty = true;
	}
	if (dirty) draw();
	requestAnimationFrame(tick);
}

// ------------------------------------------------------------------ controls
function wireUi() {
	$('clip').addEventListener('change', () => {
		selectClip(Number($('clip').value));
		draw();
	});
	$('play').addEventListener('click', () => {
		state.playing = !state.playing;
		$('play').textContent = state.playing ? 'pause' : 'play';
	});
	$('scrub').addEventListener('input', () => {
		state.time = Number($('scrub').value) / state.fps;
		draw();
	});
	$('view').addEventListener('change', () => {
		state.view = $('view').value;
		draw();
	});
	for (const id of ['body', 'wire', 'error', 'layout']) $(id).addEventListener('change', draw);
	window.addEventListener('resize', draw);
	window.addEventListener('keydown', (e) => {
		if (e.key === ' ') $('play').click();
		if (e.key === 'ArrowRight' || e.key === 'ArrowLeft') {
			const f = frameOf(state.time) + (e.key === 'ArrowRight' ? 1 : -1);
			state.time = Math.min(state.frames - 1, Math.max(0, f)) / state.fps;
			draw();
		}
	});
	// Drag turns the turntable, the wheel zooms.
	const canvas = renderer.domElement;
	let drag = null;
	canvas.addEventListener('pointerdown', (e) => (drag = [e.clientX, e.clientY]));
	window.addEventListener('pointerup', () => (drag = null));
	window.addEventListener('pointermove', (e) => {
		if (!drag || state.view !== 'turntable') return;
		state.azimuth -= (e.clientX - drag[0]) * 0.01;
		state.elevation = Math.min(1.4, Math.max(-1.4, state.elevation + (e.clientY - drag[1]) * 0.01));
		drag = [e.clientX, e.clientY];
		draw();
	});
	canvas.addEventListener('wheel', (e) => {
		e.preventDefault();
		state.distance *= Math.exp(e.deltaY * 0.001);
		draw();
	}, { passive: false });
}

// The URL hash / query sets the starting state: a link shows one frame of one clip.
function applyParams() {
	const clip = params.get('clip');
	let i = 0;
	if (clip !== null) {
		i = state.clips.findIndex((c) => c.name === clip);
		if (i < 0 && /^\d+$/.test(clip)) i = Number(clip);
		if (!(i >= 0 && i < state.clips.length)) {
			if (state.clips.length > 0) say(`no clip '${clip}' in this file; showing '${state.clips[0].name}'`);
			i = 0;
		}
	}
	if (state.clips.length > 0) {
		$('clip').value = String(i);
		selectClip(i);
	} else setupScrub();
	if (params.has('frame')) state.time = Number(params.get('frame')) / state.fps;
	else if (params.has('t')) state.time = Number(params.get('t'));
	state.time = Math.min(Math.max(0, state.time || 0), duration());
	const view = params.get('view');
	if (view && (view === 'turntable' || VIEWS[view])) state.view = view;
	$('view').value = state.view;
	const flag = (name, fallback) => (params.has(name) ? params.get(name) !== '0' : fallback);
	$('body').checked = flag('body', true);
	$('wire').checked = flag('wire', false);
	$('error').checked = flag('error', true);
	$('spin').checked = flag('spin', false);
	if (params.get('layout') === 'side') $('layout').value = 'side';
	if ($('bake')) $('bake').checked = flag('bake', true);
	state.playing = flag('play', false);
	$('play').textContent = state.playing ? 'pause' : 'play';
	document.body.classList.toggle('bare', !flag('ui', true));
}

load();
