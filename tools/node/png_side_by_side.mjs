// Puts PNG images side by side (a white gap between them) into one PNG, with pngjs.
// Usage: node tools/node/png_side_by_side.mjs OUT.png A.png B.png [...]
import { readFileSync, writeFileSync } from 'node:fs';
import { PNG } from 'pngjs';

const [output, ...inputs] = process.argv.slice(2);
if (!output || inputs.length === 0) {
	console.error('usage: png_side_by_side.mjs OUT.png A.png B.png ...');
	process.exit(2);
}
const GAP = 8;
const images = inputs.map((p) => PNG.sync.read(readFileSync(p)));
const width = images.reduce((w, i) => w + i.width, 0) + GAP * (images.length - 1);
const height = Math.max(...images.map((i) => i.height));
const out = new PNG({ width, height });
out.data.fill(255);
let x0 = 0;
for (const img of images) {
	for (let y = 0; y < img.height; y++) {
		img.data.copy(out.data, (y * width + x0) * 4, y * img.width * 4, (y + 1) * img.width * 4);
	}
	x0 += img.width + GAP;
}
writeFileSync(output, PNG.sync.write(out));
