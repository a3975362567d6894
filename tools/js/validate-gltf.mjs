// Validate a .glb with the Khronos glTF validator; print its report summary
// as JSON and exit 1 when it finds errors.
import { readFileSync } from "node:fs";
import validator from "gltf-validator";

const path = process.argv[2];
const report = await validator.validateBytes(new Uint8Array(readFileSync(path)), {
  maxIssues: 50,
  externalResourceFunction: () => Promise.reject(new Error("external resources are not expected")),
});
const { numErrors, numWarnings, numInfos, messages } = report.issues;
console.log(JSON.stringify({ path, numErrors, numWarnings, numInfos, messages: messages.slice(0, 10) }));
process.exit(numErrors > 0 ? 1 : 0);
