# The real clients the ignored tests run against what travmap writes (pinned), set
# up and exported for the shell that sources this file:
#   source .ci/clients.sh && cargo test --release -- --ignored
# Python mcap + mcap-ros2-support, rosbags, the Foxglove SDK, Ouster's SDK, rerun-sdk, pyarrow, DuckDB,
# Polars, jsonschema and scapy (packet captures); Ray and pytest; the travmap wheel (last); Node @mcap/core +
# @foxglove/rosmsg2-serialization (tests/clients/package-lock.json); Chromium for
# rerun's web viewer (tests/viewer.rs) and the labelling page, and Tesseract for the
# pictures' words (tests/pictures.rs), from Debian, as root or through sudo.
python3 -m venv target/client-venv
target/client-venv/bin/pip install --quiet --disable-pip-version-check \
    "mcap==1.6.0" "mcap-ros2-support==0.6.0" "rosbags==0.11.9" "foxglove-sdk==0.30.3" "rerun-sdk==0.41.0" \
    "pyarrow==26.0.1" "duckdb==2.0.0" "polars==2.1.0" \
    "ray==2.60.0" "pytest==9.2.0" "jsonschema==4.26.0" "plyfile==1.1.5" "laspy==2.7.0" "lazrs==0.8.2" "scapy==2.6.1"
export TRAVMAP_CLIENT_PYTHON="$PWD/target/client-venv/bin/python"
export TRAVMAP_RERUN="$PWD/target/client-venv/bin/rerun"
# Ouster's SDK writes the Ouster packets tests/ouster.rs decodes; it pins an older
# rosbags than the client venv's, so it has a venv of its own.
python3 -m venv target/ouster-venv
target/ouster-venv/bin/pip install --quiet --disable-pip-version-check "ouster-sdk==1.0.1"
export TRAVMAP_OUSTER_PYTHON="$PWD/target/ouster-venv/bin/python"
npm ci --prefix tests/clients --no-audit --no-fund --silent
if ! command -v chromium >/dev/null 2>&1 || ! command -v tesseract >/dev/null 2>&1; then
    apt_get="apt-get"
    [ "$(id -u)" -eq 0 ] || apt_get="sudo -n apt-get"
    { $apt_get update -qq && DEBIAN_FRONTEND=noninteractive $apt_get install -y -qq chromium tesseract-ocr >/dev/null; } ||
        echo "could not install chromium and tesseract-ocr: tests/viewer.rs, labelling.rs and pictures.rs will fail" >&2
fi
if command -v chromium >/dev/null 2>&1; then
    export TRAVMAP_CHROMIUM="$(command -v chromium)"
    chromium --version
fi
# Tesseract reads the pictures' words back (tests/pictures.rs).
if command -v tesseract >/dev/null 2>&1; then
    export TRAVMAP_TESSERACT="$(command -v tesseract)"
fi
# The Python wheel (scripts/build_wheel.sh: the module and the command), installed
# into a fresh virtual environment as a user installs it, with what its tests
# (python/tests/, run by tests/python.rs) read beside it.
python3 -m venv target/maturin-venv
target/maturin-venv/bin/pip install --quiet --disable-pip-version-check "maturin==1.16.0"
MATURIN="$PWD/target/maturin-venv/bin/maturin" scripts/build_wheel.sh >/dev/null
rm -rf target/wheel-venv
python3 -m venv target/wheel-venv
target/wheel-venv/bin/pip install --quiet --disable-pip-version-check target/wheels/travmap-*.whl \
    "numpy==2.4.6" "pyarrow==26.0.1" "pytest==9.2.0" "mcap==1.6.0" "mcap-ros2-support==0.6.0" "ray==2.60.0"
export TRAVMAP_WHEEL_PYTHON="$PWD/target/wheel-venv/bin/python"
