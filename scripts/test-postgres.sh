#!/usr/bin/env bash
# A throwaway PostgreSQL server on loopback for the storage tests (a ctest fixture runs it):
#   test-postgres.sh start DIR   initdb in DIR, start on a free port, write DIR/url
#                                (postgresql://hanzo@127.0.0.1:PORT/postgres)
#   test-postgres.sh stop DIR    stop it and remove DIR
# PostgreSQL refuses to run as root: as root the server runs as the `postgres` system user.
set -euo pipefail

action="$1"
dir="$2"
bin="$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -n 1)"
[ -x "$bin/initdb" ] || { echo "test-postgres: PostgreSQL server binaries not found (install the postgresql package)" >&2; exit 1; }

as_server_user() {
  if [ "$(id -u)" -eq 0 ]; then runuser -u postgres -- "$@"; else "$@"; fi
}

case "$action" in
  start)
    if [ -f "$dir/postmaster.pid" ] || [ -f "$dir/data/postmaster.pid" ]; then
      as_server_user "$bin/pg_ctl" -D "$dir/data" -m immediate stop >/dev/null 2>&1 || true
    fi
    rm -rf "$dir"
    mkdir -p "$dir"
    [ "$(id -u)" -eq 0 ] && chown postgres: "$dir"
    as_server_user "$bin/initdb" -D "$dir/data" -U hanzo -A trust --no-sync >"$dir/initdb.log" 2>&1 \
      || { cat "$dir/initdb.log" >&2; exit 1; }
    port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
    as_server_user "$bin/pg_ctl" -D "$dir/data" -l "$dir/server.log" -w -t 60 \
      -o "-p $port -k $dir -c listen_addresses=127.0.0.1 -c fsync=on" start >/dev/null \
      || { cat "$dir/server.log" >&2; exit 1; }
    echo "postgresql://hanzo@127.0.0.1:$port/postgres" > "$dir/url.tmp"
    mv "$dir/url.tmp" "$dir/url"
    echo "test-postgres: PostgreSQL on 127.0.0.1:$port ($dir)"
    ;;
  stop)
    if [ -d "$dir/data" ]; then
      as_server_user "$bin/pg_ctl" -D "$dir/data" -m fast -w stop >/dev/null 2>&1 || true
    fi
    rm -rf "$dir"
    ;;
  *)
    echo "usage: test-postgres.sh start|stop DIR" >&2
    exit 2
    ;;
esac
