#!/usr/bin/env node
// Run the Khronos glTF-Validator (an independent reader) on one .glb/.gltf.
//
// usage: node tools/node/validate.mjs FILE.glb [--json]
//        node tools/node/validate.mjs --each FILE... (one process for a whole corpus)
//   prints  "FILE: N errors, N warnings, N infos, N hints"
//   --json  prints the full validator report (JSON) on stdout instead, and
//           the summary line on stderr, so stdout stays parsable JSON
//   exit 0 only if 0 errors AND 0 warnings; else exit 1 and list the first
//   20 messages (severity, code, pointer, message) on stderr.
//   exit 2 on usage / I/O errors.
//   --each  validates every FILE and prints one JSON line per file on stdout:
//           {"file", "errors", "warnings", "codes": [error codes]}; exit 0.
import fs from 'node:fs';
import path from 'node:path';
import validator from 'gltf-validator';

const SEVERITY = ['error', 'warning', 'info', 'hint'];

function usage(msg) {
	if (msg) console.error(msg);
	console.error('usage: node validate.mjs FILE.glb|FILE.gltf [--json]');
	process.exit(2);
}

function validate(file, bytes) {
	return validator.validateBytes(bytes, {
		uri: path.basename(file),
		maxIssues: 0, // unlimited: the test wants to see everything
		writeTimestamp: false, // reproducible reports
		// .gltf + .bin (or external images) are resolved relative to the file,
		// so external buffers get validated too instead of being skipped.
		externalResourceFunction: (uri) =>
			new Promise((resolve, reject) => {
				const p = path.resolve(path.dirname(file), decodeURIComponent(uri));
				fs.readFile(p, (err, data) => (err ? reject(err.toString()) : resolve(new Uint8Array(data))));
			}),
	});
}

const args = process.argv.slice(2);
const files = args.filter((a) => !a.startsWith('--'));
if (args.includes('--each')) {
	for (const file of files) {
		let line;
		try {
			const r = await validate(file, new Uint8Array(fs.readFileSync(file)));
			const codes = r.issues.messages.filter((m) => m.severity === 0).map((m) => m.code);
			line = { file, errors: r.issues.numErrors, warnings: r.issues.numWarnings, codes: [...new Set(codes)] };
		} catch (e) {
			// rejection = not glTF at all / unreadable container: an error like any other
			line = { file, errors: 1, warnings: 0, codes: ['REJECTED'], message: String(e) };
		}
		console.log(JSON.stringify(line));
	}
	process.exit(0);
}
const wantJson = args.includes('--json');
if (files.length !== 1 || args.some((a) => a.startsWith('--') && a !== '--json')) usage();
const file = files[0];

let bytes;
try {
	bytes = new Uint8Array(fs.readFileSync(file));
} catch (e) {
	usage(`cannot read ${file}: ${e.message}`);
}

const report = await validate(file, bytes).catch((e) => {
	// rejection = not glTF at all / unreadable container
	console.error(`${file}: validator failed: ${e}`);
	process.exit(1);
});

const iss = report.issues;
const summary = `${file}: ${iss.numErrors} errors, ${iss.numWarnings} warnings, ${iss.numInfos} infos, ${iss.numHints} hints`;
if (wantJson) {
	// keep stdout pure JSON (parsable by the caller); summary goes to stderr
	console.error(summary);
	console.log(JSON.stringify(report, null, 2));
} else {
	console.log(summary);
}

const ok = iss.numErrors === 0 && iss.numWarnings === 0;
if (!ok) {
	// most severe first, so the 20 shown are the ones that fail the check
	const msgs = [...iss.messages].sort((a, b) => a.severity - b.severity).slice(0, 20);
	for (const m of msgs) {
		console.error(`  ${SEVERITY[m.severity] ?? m.severity} ${m.code} ${m.pointer ?? ''}${m.offset !== undefined ? ` @${m.offset}` : ''}: ${m.message}`);
	}
}
process.exit(ok ? 0 : 1);
