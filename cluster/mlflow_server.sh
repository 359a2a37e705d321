#!/usr/bin/env bash
# A shared MLflow tracking server as a lab runs it: `mlflow server` with a PostgreSQL backend store and
# proxied artifacts in one folder, bound to localhost.
#
#   cluster/mlflow_server.sh start [DIR]   # DIR: default /tmp/topoloc-mlflow; prints the line to export
#   export MLFLOW_TRACKING_URI=http://127.0.0.1:5000   # every stage run (and `mlflow ui` users) go there
#   cluster/mlflow_server.sh stop [DIR]    # stops the server and PostgreSQL started by `start`
#
# PG_PORT (default 55432) and MLFLOW_PORT (default 5000) pick the ports; MLFLOW_HOST (default 127.0.0.1) the
# address: set it to 0.0.0.0 only on purpose (the server has no authentication). Needs PostgreSQL's server
# binaries (apt-get install postgresql) and psycopg2 (pip install -e ".[cluster]"); PostgreSQL runs as user
# postgres with its data in DIR/pg, the artifacts are kept in DIR/artifacts.
set -euo pipefail

command=${1:-}
dir=$(realpath -m "${2:-/tmp/topoloc-mlflow}")
pg_port=${PG_PORT:-55432}
port=${MLFLOW_PORT:-5000}
host=${MLFLOW_HOST:-127.0.0.1}
pg_bin=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -1 || true)

stop() {
    if [[ -f "$dir/mlflow.pid" ]]; then
        pid=$(cat "$dir/mlflow.pid")
        kill -- "-$pid" 2>/dev/null || true  # the server, its workers and its job consumers
        for _ in $(seq 300); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
        kill -KILL -- "-$pid" 2>/dev/null || true
        rm -f "$dir/mlflow.pid"
    fi
    if [[ -n "$pg_bin" && -f "$dir/pg/postmaster.pid" ]]; then
        runuser -u postgres -- "$pg_bin/pg_ctl" -D "$dir/pg" -m fast -w stop >/dev/null || true
    fi
}

start() {
    [[ -x "$pg_bin/initdb" ]] || { echo "mlflow_server.sh: PostgreSQL not found (apt-get install postgresql)" >&2; exit 2; }
    command -v mlflow >/dev/null || { echo "mlflow_server.sh: mlflow not on PATH (activate the environment)" >&2; exit 2; }
    python -c "import psycopg2" 2>/dev/null || { echo "mlflow_server.sh: psycopg2 missing (pip install -e '.[cluster]')" >&2; exit 2; }
    stop
    mkdir -p "$dir/artifacts" "$dir/pg-socket"
    chown postgres: "$dir" "$dir/pg-socket"
    runuser -u postgres -- test -x "$dir" || { echo "mlflow_server.sh: $dir: user postgres cannot enter it (a parent folder is private)" >&2; exit 2; }
    if [[ ! -f "$dir/pg/PG_VERSION" ]]; then
        runuser -u postgres -- "$pg_bin/initdb" -D "$dir/pg" -A trust -U postgres >"$dir/initdb.log"
    fi
    runuser -u postgres -- "$pg_bin/pg_ctl" -D "$dir/pg" -l "$dir/postgresql.log" -w \
        -o "-p $pg_port -k $dir/pg-socket -c listen_addresses=localhost" start >/dev/null
    runuser -u postgres -- psql -h "$dir/pg-socket" -p "$pg_port" -U postgres -tAc \
        "SELECT 1 FROM pg_database WHERE datname = 'mlflow'" | grep -q 1 ||
        runuser -u postgres -- psql -h "$dir/pg-socket" -p "$pg_port" -U postgres -c "CREATE DATABASE mlflow" >/dev/null
    setsid mlflow server --backend-store-uri "postgresql://postgres@localhost:$pg_port/mlflow" \
        --artifacts-destination "$dir/artifacts" --host "$host" --port "$port" --workers 2 \
        >"$dir/mlflow.log" 2>&1 &
    echo $! >"$dir/mlflow.pid"
    for _ in $(seq 300); do
        if curl -fs "http://127.0.0.1:$port/health" >/dev/null 2>&1; then
            echo "export MLFLOW_TRACKING_URI=http://127.0.0.1:$port"
            return 0
        fi
        kill -0 "$(cat "$dir/mlflow.pid")" 2>/dev/null || break
        sleep 0.5
    done
    echo "mlflow_server.sh: the server did not come up; see $dir/mlflow.log" >&2
    stop
    exit 1
}

case "$command" in
    start) start ;;
    stop) stop ;;
    *) echo "usage: $0 start|stop [DIR]" >&2; exit 2 ;;
esac
