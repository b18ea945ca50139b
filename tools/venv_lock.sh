# Sourced by the tools/*_setup.sh scripts: serialise installs into one virtual environment.
# Several tests of one `cargo test` run call the same setup script at once; without the lock
# two pips install into the same fresh venv together and one of them fails on the other's
# half-written package metadata. `venv_lock VENV` takes an exclusive lock on VENV.lock (held
# until the script exits; waits up to 30 min for another install to finish). `venv_fresh VENV`
# (re)creates the venv empty, so a venv left half-installed by an interrupted run is rebuilt
# rather than patched.
venv_lock() {
    mkdir -p "$(dirname "$1")"
    if command -v flock >/dev/null; then
        exec 9>"$1.lock"
        flock -w 1800 9 || { echo "$(basename "$0"): timed out waiting for the lock $1.lock" >&2; exit 1; }
    fi
}
venv_fresh() {
    "${PYTHON:-python3}" -m venv --clear "$1"
}
