// Validate a .glb/.gltf with the pinned Khronos glTF Validator; print the JSON report.
// Usage: node validate.js FILE   (exit code 0 when the report could be produced)
"use strict";
const fs = require("fs");
const validator = require("gltf-validator");

const file = process.argv[2];
validator
  .validateBytes(new Uint8Array(fs.readFileSync(file)), {
    maxIssues: 0,
    externalResourceFunction: () => Promise.reject(new Error("no external resources")),
  })
  .then((report) => process.stdout.write(JSON.stringify(report, null, 1)))
  .catch((err) => {
    process.stderr.write(String(err) + "\n");
    process.exit(2);
  });
