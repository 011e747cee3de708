#!/usr/bin/env python3
"""Validate CITATION.cff against the Citation File Format 1.2.0 schema and check it agrees with Cargo.toml.

Usage: check_citation.py REPO_ROOT CFF_WHEEL_DIR
The schema is read from cffconvert's wheel (scripts/setup.sh downloads it), the file with PyYAML and the
validation done by jsonschema (Draft 7, the schema's own draft). Prints one line per problem; exit 1 if any.
"""
import glob
import json
import os
import sys
import tomllib
import zipfile

import jsonschema
import yaml


def main() -> int:
    root, wheel_dir = sys.argv[1], sys.argv[2]
    wheels = sorted(glob.glob(os.path.join(wheel_dir, "cffconvert-2.0.0-*.whl")))
    if not wheels:
        print(f"{wheel_dir}: no cffconvert 2.0.0 wheel (run scripts/setup.sh)")
        return 1
    with zipfile.ZipFile(wheels[0]) as z:
        schema = json.loads(z.read("cffconvert/schemas/1.2.0/schema.json"))
    with open(os.path.join(root, "CITATION.cff"), encoding="utf-8") as f:
        cff = yaml.safe_load(f)
    with open(os.path.join(root, "Cargo.toml"), "rb") as f:
        package = tomllib.load(f)["package"]
    problems = [
        f"CITATION.cff: {'/'.join(map(str, e.path)) or '(root)'}: {e.message}"
        for e in jsonschema.Draft7Validator(schema).iter_errors(cff)
    ]
    if str(cff.get("version")) != package["version"]:
        problems.append(f"CITATION.cff: version {cff.get('version')} but Cargo.toml says {package['version']}")
    licences = sorted(cff.get("license") or [])
    cargo_licences = sorted(x.strip() for x in package["license"].split(" OR "))
    if licences != cargo_licences:
        problems.append(f"CITATION.cff: license {licences} but Cargo.toml says {cargo_licences}")
    for spdx in cargo_licences:
        name = {"MIT": "LICENSE-MIT", "Apache-2.0": "LICENSE-APACHE"}.get(spdx)
        if name is None or not os.path.isfile(os.path.join(root, name)):
            problems.append(f"{name or spdx}: no licence file for {spdx} in the repository root")
    for p in problems:
        print(p)
    if not problems:
        print(f"CITATION.cff valid (CFF {cff['cff-version']}), licences {', '.join(cargo_licences)} present")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
