// Validates glTF files with the Khronos glTF-Validator; exits non-zero when a report
// has errors (or, with MENISCUS_GLTF_STRICT=1, warnings).
// Usage: node validate_gltf.mjs FILE...   (run with NODE_PATH pointing at the package)
import { createRequire } from "module";
import { readFile } from "fs/promises";
import path from "path";

const require = createRequire(path.join(process.env.GLTF_VALIDATOR_DIR ?? process.cwd(), "noop.js"));
const validator = require("gltf-validator");

let failed = false;
for (const file of process.argv.slice(2)) {
  const data = new Uint8Array(await readFile(file));
  const report = await validator.validateBytes(data, {
    uri: path.basename(file),
    maxIssues: 50,
    externalResourceFunction: (uri) => readFile(path.join(path.dirname(file), decodeURIComponent(uri))).then((b) => new Uint8Array(b)),
  });
  const i = report.issues;
  console.log(`${file}: ${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos, ${i.numHints} hints`);
  for (const m of i.messages) {
    if (m.severity <= 1) console.log(`  [${m.severity === 0 ? "error" : "warning"}] ${m.code} ${m.pointer ?? ""}: ${m.message}`);
  }
  if (i.numErrors > 0 || (process.env.MENISCUS_GLTF_STRICT === "1" && i.numWarnings > 0)) failed = true;
}
process.exit(failed ? 1 : 0);
