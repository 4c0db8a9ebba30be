#!/usr/bin/env node
// validate_gltf.js -- check one .glb / .gltf file with the Khronos glTF
// validator (npm package gltf-validator, pinned in package.json and
// installed into tests/tools/node_modules by deploy/install-deps.sh).
//
// Usage: node tests/tools/validate_gltf.js FILE
// Prints the validator's issue counts, then every message (code,
// severity, JSON pointer, text).  Exit status: 0 when the validator
// reports no error (warnings, infos and hints are printed but allowed),
// 1 when it reports errors or cannot read the asset at all, 2 on usage
// (wrong arguments, unreadable file, validator not installed).
//
// External resources are not fetched: luxrad writes self-contained files
// (GLB, or .gltf with data: URIs), so an external URI is itself a finding.
'use strict';

const fs = require('fs');
const path = require('path');

const SEVERITY = ['error', 'warning', 'info', 'hint'];

function usage(msg) {
	if (msg)
		process.stderr.write(`validate_gltf: ${msg}\n`);
	process.stderr.write('usage: node tests/tools/validate_gltf.js FILE.glb\n');
	process.exit(2);
}

function loadValidator() {
	try {
		return require('gltf-validator');
	} catch (e) {
		usage('the gltf-validator package is not installed (' +
		      e.message.split('\n')[0] + '); run deploy/install-deps.sh');
	}
	return null;
}

function printReport(file, report) {
	const is = report.issues;
	const v = report.validatorVersion || '?';
	process.stdout.write(
	    `${file}: glTF validator ${v}: ${is.numErrors} errors, ` +
	    `${is.numWarnings} warnings, ${is.numInfos} infos, ` +
	    `${is.numHints} hints\n`);
	for (const m of is.messages) {
		const sev = SEVERITY[m.severity] || String(m.severity);
		const where = m.pointer ? ` at ${m.pointer}` :
		              (m.offset !== undefined ? ` at byte ${m.offset}` : '');
		process.stdout.write(`  ${sev} ${m.code}${where}: ${m.message}\n`);
	}
	if (is.truncated)
		process.stdout.write('  (more issues not listed)\n');
}

async function main(argv) {
	if (argv.length !== 1 || argv[0].startsWith('-'))
		usage(argv.length ? null : 'no file given');
	const file = argv[0];
	let bytes;
	try {
		bytes = fs.readFileSync(file);
	} catch (e) {
		usage(`cannot read ${file}: ${e.message}`);
	}
	const validator = loadValidator();
	let report;
	try {
		report = await validator.validateBytes(new Uint8Array(bytes), {
			uri: path.basename(file),
			maxIssues: 0,
			writeTimestamp: false,
		});
	} catch (e) {
		// The validator rejects what it cannot even parse as glTF/GLB.
		process.stdout.write(`${file}: not a glTF asset: ${e}\n`);
		return 1;
	}
	printReport(file, report);
	return report.issues.numErrors === 0 ? 0 : 1;
}

main(process.argv.slice(2)).then(
    (code) => process.exit(code),
    (e) => {
	    process.stderr.write(`validate_gltf: ${e && e.stack || e}\n`);
	    process.exit(2);
    });
