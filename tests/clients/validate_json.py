"""Validates travmap's --json output against its JSON Schema.

usage: validate_json.py SCHEMA_DIR COMMAND STDOUT_FILE STDERR_FILE
Every stdout line must match schemas/json/COMMAND.schema.json; an error record on
stderr (a line that is a JSON object) must match error.schema.json. Prints the number
of records checked; exits non-zero with the first violation.
"""

import json
import sys
from pathlib import Path

import jsonschema


def validator(schema_dir: Path, name: str) -> jsonschema.Draft202012Validator:
    schema = json.loads((schema_dir / f"{name}.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def main() -> None:
    schema_dir, command, stdout, stderr = Path(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
    checked = 0
    lines = [line for line in Path(stdout).read_text().splitlines() if line]
    if lines:
        output = validator(schema_dir, command)
        for line in lines:
            output.validate(json.loads(line))
            checked += 1
    # Notices are lines of text on stderr; an error is its last line, one JSON object.
    errors = [line for line in Path(stderr).read_text().splitlines() if line.startswith("{")]
    if errors:
        validator(schema_dir, "error").validate(json.loads(errors[-1]))
        checked += 1
    print(json.dumps({"checked": checked}))


if __name__ == "__main__":
    main()
