// Upload one file with tus-js-client (the tus project's JavaScript client) under node.
//   node upload.js ENDPOINT API_KEY FILE CHUNK_BYTES
// Prints {"url": ...} when the upload is complete; exits 1 with the error otherwise.
"use strict";
const fs = require("node:fs");
const path = require("node:path");
const tus = require("tus-js-client");

const [endpoint, key, file, chunk] = process.argv.slice(2);
const data = fs.readFileSync(file);
const upload = new tus.Upload(data, {
  endpoint,
  headers: { Authorization: `Bearer ${key}` },
  chunkSize: Number(chunk),
  retryDelays: Array(60).fill(250), // a cut connection is tried again, from the server's offset
  metadata: { filename: path.basename(file), name: "site walk", tags: "tus,level 2" },
  storeFingerprintForResuming: false,
  onError(error) {
    process.stderr.write(`${error}\n`);
    process.exit(1);
  },
  onSuccess() {
    process.stdout.write(`${JSON.stringify({ url: upload.url })}\n`);
  },
});
upload.start();
