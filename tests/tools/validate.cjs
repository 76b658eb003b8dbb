// Validate glTF/GLB files with the Khronos glTF Validator.
// Usage: node validate.cjs FILE...  ->  one JSON line per file on stdout:
// {"file", "errors", "warnings", "infos", "hints", "messages": [errors and warnings]}
const fs = require("fs");
const path = require("path");
const validator = require("gltf-validator");

async function validate(file) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 0,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)), (err, data) =>
          err ? reject(err.toString()) : resolve(new Uint8Array(data)));
      }),
  });
  const issues = report.issues;
  return {
    file,
    errors: issues.numErrors,
    warnings: issues.numWarnings,
    infos: issues.numInfos,
    hints: issues.numHints,
    messages: issues.messages.filter((m) => m.severity <= 1),
    info: report.info,
  };
}

(async () => {
  for (const file of process.argv.slice(2)) {
    process.stdout.write(JSON.stringify(await validate(file)) + "\n");
  }
})().catch((err) => {
  process.stderr.write(String(err) + "\n");
  process.exit(1);
});
