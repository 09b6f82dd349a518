// Writes a copy of a glb whose morph targets carry POSITION deltas only (their NORMAL deltas
// dropped from the targets; the accessors stay, unused): the bake as it was before morph
// normals, for before/after renders (scripts/morph_normals_render.sh).
// Usage: node tools/node/strip_morph_normals.mjs IN.glb OUT.glb
import { readFileSync, writeFileSync } from 'node:fs';

const [input, output] = process.argv.slice(2);
if (!input || !output) {
	console.error('usage: strip_morph_normals.mjs IN.glb OUT.glb');
	process.exit(2);
}
const glb = readFileSync(input);
if (glb.toString('latin1', 0, 4) !== 'glTF') throw new Error(`${input}: not a glb`);
const jsonLength = glb.readUInt32LE(12);
const json = JSON.parse(glb.toString('utf8', 20, 20 + jsonLength));
let dropped = 0;
for (const mesh of json.meshes || []) {
	for (const primitive of mesh.primitives) {
		for (const target of primitive.targets || []) {
			if ('NORMAL' in target) {
				delete target.NORMAL;
				dropped++;
			}
		}
	}
}
let text = JSON.stringify(json);
while (Buffer.byteLength(text) % 4 !== 0) text += ' ';
const chunk = Buffer.from(text);
const rest = glb.subarray(20 + jsonLength);
const header = Buffer.alloc(20);
header.write('glTF', 0, 'latin1');
header.writeUInt32LE(2, 4);
header.writeUInt32LE(20 + chunk.length + rest.length, 8);
header.writeUInt32LE(chunk.length, 12);
header.writeUInt32LE(0x4e4f534a, 16);
writeFileSync(output, Buffer.concat([header, chunk, rest]));
console.log(`${output}: ${dropped} NORMAL deltas dropped`);
