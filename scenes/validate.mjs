// Runs the Khronos glTF validator on every shipped scene and fixture:
//   npm install -g gltf-validator && NODE_PATH=$(npm root -g) node scenes/validate.mjs
// Prints each file's error, warning and info counts and every error and warning; exits 1
// when any file has an error or a warning.
import { createRequire } from "module";
import { readFileSync, readdirSync } from "fs";
import { join, dirname } from "path";
import { fileURLToPath } from "url";

const require = createRequire(import.meta.url);
const validator = require("gltf-validator");
const here = dirname(fileURLToPath(import.meta.url));
const files = [];
for (const dir of [here, join(here, "fixtures"), join(here, "blender"), join(here, "khronos")]) {
  for (const f of readdirSync(dir)) {
    if (f.endsWith(".gltf") || f.endsWith(".glb")) files.push(join(dir, f));
  }
}
let bad = 0;
for (const file of files.sort()) {
  const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), {
    uri: file,
    externalResourceFunction: (uri) =>
      Promise.resolve(new Uint8Array(readFileSync(join(dirname(file), decodeURIComponent(uri))))),
  });
  const i = report.issues;
  console.log(`${file.slice(here.length + 1)}: ${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos`);
  for (const m of i.messages.filter((m) => m.severity <= 1)) {
    console.log(`  ${m.severity === 0 ? "error" : "warning"} ${m.code} ${m.pointer ?? ""}: ${m.message}`);
  }
  if (i.numErrors + i.numWarnings > 0) bad++;
}
process.exit(bad ? 1 : 0);
