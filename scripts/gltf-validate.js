// Validates glTF files with the Khronos glTF validator that scripts/nodetools.sh installs into
// .deps/nodetools: `node scripts/gltf-validate.js FILE...`. Prints one JSON line per file
// ({file, errors, warnings, infos, messages}) and exits 1 when any file has errors.
const path = require('path');
const fs = require('fs');
const validator = require(path.join(__dirname, '..', '.deps', 'nodetools', 'node_modules', 'gltf-validator'));

async function validate(file) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const external = (uri) => fs.promises.readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)))
    .then((data) => new Uint8Array(data));
  const report = await validator.validateBytes(bytes, { uri: file, externalResourceFunction: external });
  const issues = report.issues;
  const messages = issues.messages.filter((m) => m.severity <= 1).slice(0, 10);
  console.log(JSON.stringify({ file, errors: issues.numErrors, warnings: issues.numWarnings, infos: issues.numInfos, messages }));
  return issues.numErrors;
}

(async () => {
  let errors = 0;
  for (const file of process.argv.slice(2)) {
    errors += await validate(file);
  }
  process.exit(errors > 0 ? 1 : 0);
})();
