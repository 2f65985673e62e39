#!/usr/bin/env node
// Validates glTF/GLB files with the Khronos glTF validator and prints one JSON line per file:
// {"file", "errors", "warnings", "infos", "messages": [{code, severity, pointer, message}]}.
// Exit status: 0 when every file has no errors and no warnings, 1 otherwise, 2 on bad usage.
'use strict';
const fs = require('fs');
const path = require('path');
const validator = require('gltf-validator');

const SEVERITY = ['error', 'warning', 'info', 'hint'];

async function validate(file) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 100,
    // GLBs written by fresco are self-contained; an external reference is an error.
    externalResourceFunction: (uri) => Promise.reject(new Error(`external resource ${uri}`)),
  });
  const issues = report.issues;
  return {
    file,
    errors: issues.numErrors,
    warnings: issues.numWarnings,
    infos: issues.numInfos,
    messages: issues.messages.map((m) => ({
      code: m.code,
      severity: SEVERITY[m.severity] || String(m.severity),
      pointer: m.pointer,
      message: m.message,
    })),
  };
}

async function main() {
  const files = process.argv.slice(2);
  if (files.length === 0) {
    console.error('usage: validate.js FILE.glb...');
    process.exit(2);
  }
  let ok = true;
  for (const file of files) {
    try {
      const result = await validate(file);
      console.log(JSON.stringify(result));
      if (result.errors > 0 || result.warnings > 0) ok = false;
    } catch (e) {
      console.log(JSON.stringify({ file, errors: 1, warnings: 0, infos: 0,
        messages: [{ code: 'UNREADABLE', severity: 'error', message: String(e) }] }));
      ok = false;
    }
  }
  process.exit(ok ? 0 : 1);
}

main();
