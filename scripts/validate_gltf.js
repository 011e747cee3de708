#!/usr/bin/env node
// Runs the Khronos glTF validator (npm package `gltf-validator`, a devDependency in package.json at the
// repository root; install it with `npm ci`) on one .glb/.gltf file and prints its JSON report on stdout.
//
// Usage: node scripts/validate_gltf.js FILE [MAX_ISSUES]
// Exit status: 0 when the validator ran (whatever it found: read report.issues.numErrors),
//              2 on usage errors, 3 when the validator is not installed, 4 when it could not run.
'use strict';

const fs = require('fs');
const path = require('path');

function main() {
  const args = process.argv.slice(2);
  if (args.length < 1 || args.length > 2) {
    process.stderr.write('usage: node scripts/validate_gltf.js FILE [MAX_ISSUES]\n');
    process.exit(2);
  }
  const file = path.resolve(args[0]);
  const maxIssues = args.length === 2 ? Number(args[1]) : 0;
  if (!Number.isInteger(maxIssues) || maxIssues < 0) {
    process.stderr.write(`MAX_ISSUES must be a non-negative integer, got ${JSON.stringify(args[1])}\n`);
    process.exit(2);
  }

  let validator;
  try {
    validator = require('gltf-validator');
  } catch (e) {
    process.stderr.write(
      `gltf-validator is not installed (${e.message}); run \`npm ci\` at the repository root\n`);
    process.exit(3);
  }

  let bytes;
  try {
    bytes = fs.readFileSync(file);
  } catch (e) {
    process.stderr.write(`cannot read ${file}: ${e.message}\n`);
    process.exit(2);
  }

  validator
    .validateBytes(new Uint8Array(bytes), {
      uri: path.basename(file),
      maxIssues: maxIssues,
      writeTimestamp: false,
      // Resources outside the file are reported as missing rather than loaded.
      externalResourceFunction: (uri) =>
        new Promise((resolve, reject) => {
          const p = path.resolve(path.dirname(file), decodeURIComponent(uri));
          fs.readFile(p, (err, data) => (err ? reject(err.toString()) : resolve(new Uint8Array(data))));
        }),
    })
    .then((report) => {
      process.stdout.write(JSON.stringify(report, null, 2) + '\n');
    })
    .catch((err) => {
      process.stderr.write(`gltf-validator could not validate ${file}: ${err}\n`);
      process.exit(4);
    });
}

main();
