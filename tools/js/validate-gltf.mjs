// Validate .glb files with the Khronos glTF validator: print one line of
// JSON per file (its report's summary) and exit 1 when any has errors.
//
//   node validate-gltf.mjs FILE.glb [FILE.glb ...]
import { readFileSync } from "node:fs";
import validator from "gltf-validator";

let failed = false;
for (const path of process.argv.slice(2)) {
  const report = await validator.validateBytes(new Uint8Array(readFileSync(path)), {
    maxIssues: 50,
    externalResourceFunction: () => Promise.reject(new Error("external resources are not expected")),
  });
  const { numErrors, numWarnings, numInfos, messages } = report.issues;
  console.log(JSON.stringify({ path, numErrors, numWarnings, numInfos, messages: messages.slice(0, 10) }));
  failed ||= numErrors > 0;
}
process.exit(failed ? 1 : 0);
