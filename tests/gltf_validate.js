// Validate glTF/GLB files with the Khronos glTF validator (npm package gltf-validator):
//   node gltf_validate.js VALIDATOR_DIR FILE...   -> one JSON line per file: {file, errors, warnings, messages}
const fs = require('fs');
const path = require('path');
const validator = require(process.argv[2]);
(async () => {
  for (const file of process.argv.slice(3)) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
      uri: path.basename(file), maxIssues: 100,
      externalResourceFunction: () => Promise.reject(new Error('no external resources')),
    });
    console.log(JSON.stringify({file, errors: report.issues.numErrors, warnings: report.issues.numWarnings,
      infos: report.issues.numInfos, messages: report.issues.messages.filter(m => m.severity <= 1).slice(0, 10)}));
  }
})().catch(e => { console.error(String(e)); process.exit(1); });
