#!/usr/bin/env bash
# Several `hanzo-fusion serve` replicas behind nginx on one machine (docs/server.md "Replicas"):
# PostgreSQL (sessions, trajectories, leases), a local S3 (s3rver from npm: maps, recordings),
# N replicas and nginx with session affinity for REST and gRPC.
#
#   replicas.sh start DIR [REPLICAS [REST_PORT [GRPC_PORT]]]   (defaults: 3, 8083, 8084)
#   replicas.sh stop DIR
#
# DIR keeps everything: postgres/, s3/, replica-N/ (data folder, log), nginx.conf, and
# DIR/endpoints.json ({"rest_url", "grpc_address", "replicas": [{"id", "pid", "rest_port", ...}]}).
# The replicas' tokens come from HANZO_FUSION_TOKENS_FILE (unset: they run with
# --insecure-no-auth, for a trial on one machine only). HANZO_FUSION lists the binary
# (default build/apps/hanzo-fusion); HANZO_FUSION_LEASE_S the lease (default 10 s).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/.." && pwd)"
action="${1:-}"
dir="${2:-}"
[ -n "$action" ] && [ -n "$dir" ] || { echo "usage: replicas.sh start|stop DIR [REPLICAS [REST_PORT [GRPC_PORT]]]" >&2; exit 2; }

free_port() { /usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }

# Stops what DIR lists, front to back: nginx, the replicas (they commit their poses and save
# their maps first: up to 20 s each, then killed), the object store, PostgreSQL.
stop_all() {
  [ -f "$dir/nginx.pid" ] && kill "$(cat "$dir/nginx.pid")" 2>/dev/null || true
  local pids=()
  for pid_file in "$dir"/replica-*/pid; do
    [ -f "$pid_file" ] && pids+=("$(cat "$pid_file")")
  done
  [ ${#pids[@]} -gt 0 ] && kill "${pids[@]}" 2>/dev/null || true
  for pid in "${pids[@]}"; do
    for _ in $(seq 200); do
      state="$(cut -d' ' -f3 "/proc/$pid/stat" 2>/dev/null || echo gone)"  # Z: exited, not yet reaped
      [ "$state" = gone ] || [ "$state" = Z ] && break
      sleep 0.1
    done
    kill -9 "$pid" 2>/dev/null || true
  done
  [ -f "$dir/s3/pid" ] && kill "$(cat "$dir/s3/pid")" 2>/dev/null || true
  [ -d "$dir/postgres" ] && bash "$here/test-postgres.sh" stop "$dir/postgres" || true
}

case "$action" in
  stop)
    stop_all
    exit 0
    ;;
  start) ;;
  *)
    echo "usage: replicas.sh start|stop DIR [REPLICAS [REST_PORT [GRPC_PORT]]]" >&2
    exit 2
    ;;
esac

replicas="${3:-3}"
rest_port="${4:-8083}"
grpc_port="${5:-8084}"
binary="${HANZO_FUSION:-$repo/build/apps/hanzo-fusion}"
lease_s="${HANZO_FUSION_LEASE_S:-10}"
[ -x "$binary" ] || { echo "replicas: $binary not found (make build, or set HANZO_FUSION)" >&2; exit 1; }
nginx_bin="$(command -v nginx || echo /usr/sbin/nginx)"
[ -x "$nginx_bin" ] || { echo "replicas: nginx not found (scripts/install-deps.sh installs it)" >&2; exit 1; }
s3rver="$repo/tests/s3server/node_modules/s3rver/bin/s3rver.js"
[ -f "$s3rver" ] || { echo "replicas: $s3rver not found (scripts/install-deps.sh installs it)" >&2; exit 1; }
mkdir -p "$dir"
dir="$(cd "$dir" && pwd)"
[ "$(id -u)" -eq 0 ] && chmod 755 "$dir"  # PostgreSQL runs as the postgres user (scripts/test-postgres.sh)
trap 'echo "replicas: start failed; stopping what started" >&2; stop_all' ERR

# PostgreSQL: one database for every replica.
bash "$here/test-postgres.sh" start "$dir/postgres" >/dev/null
database="$(cat "$dir/postgres/url")"

# The object store: s3rver with bucket "fusion".
mkdir -p "$dir/s3"
s3_port="$(free_port)"
node --openssl-legacy-provider "$s3rver" -d "$dir/s3/data" -a 127.0.0.1 -p "$s3_port" --configure-bucket fusion >"$dir/s3/log.txt" 2>&1 &
echo $! >"$dir/s3/pid"
for _ in $(seq 200); do grep -q "listening" "$dir/s3/log.txt" && break; sleep 0.05; done
grep -q "listening" "$dir/s3/log.txt" || { cat "$dir/s3/log.txt" >&2; false; }
export AWS_ACCESS_KEY_ID="${AWS_ACCESS_KEY_ID:-S3RVER}" AWS_SECRET_ACCESS_KEY="${AWS_SECRET_ACCESS_KEY:-S3RVER}"
object_store="s3://fusion?endpoint=http://127.0.0.1:$s3_port"

# The replicas share a secret for handing sessions to each other.
if [ -z "${HANZO_FUSION_REPLICA_SECRET:-}" ]; then
  HANZO_FUSION_REPLICA_SECRET="$(head -c 24 /dev/urandom | base64)"
fi
export HANZO_FUSION_REPLICA_SECRET
auth=(--insecure-no-auth)
[ -n "${HANZO_FUSION_TOKENS_FILE:-}" ] && auth=(--tokens "$HANZO_FUSION_TOKENS_FILE")

rest_servers=""
grpc_servers=""
replica_json=""
for i in $(seq 1 "$replicas"); do
  folder="$dir/replica-$i"
  mkdir -p "$folder"
  port="$(free_port)"
  gport="$(free_port)"
  "$binary" serve --replica-id "replica-$i" --bind 127.0.0.1 --port "$port" --grpc-port "$gport" --lease-s "$lease_s" \
    --db "$database" --object-store "$object_store" --data-dir "$folder/data" "${auth[@]}" >"$folder/log.txt" 2>&1 &
  echo $! >"$folder/pid"
  rest_servers+="    server 127.0.0.1:$port max_fails=1 fail_timeout=2s;"$'\n'
  grpc_servers+="    server 127.0.0.1:$gport max_fails=1 fail_timeout=2s;"$'\n'
  replica_json+="${replica_json:+, }{\"id\": \"replica-$i\", \"pid\": $(cat "$folder/pid"), \"rest_port\": $port, \"grpc_port\": $gport}"
done
for i in $(seq 1 "$replicas"); do
  for _ in $(seq 300); do grep -q "REST on" "$dir/replica-$i/log.txt" && break; sleep 0.1; done
  grep -q "REST on" "$dir/replica-$i/log.txt" || { echo "replicas: replica-$i did not start:" >&2; cat "$dir/replica-$i/log.txt" >&2; false; }
done

# nginx: REST requests of a session and its gRPC streams (metadata x-session-id) hash to the
# same replica (both upstreams list the replicas in the same order; a consistent hash would place
# the REST and gRPC addresses on different rings); other requests are spread. A replica that does
# not answer is skipped (the key is hashed again).
user_line=""
[ "$(id -u)" -eq 0 ] && user_line="user root;"
mkdir -p "$dir/nginx"
cat >"$dir/nginx.conf" <<EOF
$user_line
worker_processes 2;
pid $dir/nginx.pid;
error_log $dir/nginx/error.log warn;
events { worker_connections 4096; }
http {
  access_log off;
  client_body_temp_path $dir/nginx/body;
  proxy_temp_path $dir/nginx/proxy;
  fastcgi_temp_path $dir/nginx/fastcgi;
  uwsgi_temp_path $dir/nginx/uwsgi;
  scgi_temp_path $dir/nginx/scgi;
  client_max_body_size 64m;

  # The session a request is about: /v1/sessions/ID/..., or gRPC metadata x-session-id.
  map \$uri \$hanzo_rest_key {
    ~^/v1/sessions/(?<session>[0-9A-Za-z_-]+) \$session;
    default \$request_id;
  }
  map \$http_x_session_id \$hanzo_grpc_key {
    "" \$request_id;
    default \$http_x_session_id;
  }
  upstream hanzo_rest {
    hash \$hanzo_rest_key;
$rest_servers    keepalive 64;
  }
  upstream hanzo_grpc {
    hash \$hanzo_grpc_key;
$grpc_servers  }
  server {
    listen 127.0.0.1:$rest_port;
    location / {
      proxy_pass http://hanzo_rest;
      proxy_http_version 1.1;
      proxy_set_header Connection "";
      proxy_set_header Host \$host;
      proxy_buffering off;
      proxy_read_timeout 3600s;
      proxy_next_upstream error timeout;
    }
  }
  server {
    listen 127.0.0.1:$grpc_port http2;
    # A gRPC stream is one request whose body grows for as long as the robot streams: no size
    # limit (64m would cut a LiDAR stream after about 110 sweeps of 30k points).
    client_max_body_size 0;
    location / {
      grpc_pass grpc://hanzo_grpc;
      grpc_read_timeout 3600s;
      grpc_send_timeout 3600s;
      grpc_next_upstream error timeout;
    }
  }
}
EOF
"$nginx_bin" -c "$dir/nginx.conf" -p "$dir/nginx" -e "$dir/nginx/error.log"
for _ in $(seq 100); do [ -f "$dir/nginx.pid" ] && break; sleep 0.05; done

cat >"$dir/endpoints.json" <<EOF
{"rest_url": "http://127.0.0.1:$rest_port", "grpc_address": "127.0.0.1:$grpc_port", "database": "$database",
 "object_store": "$object_store", "lease_s": $lease_s, "replicas": [$replica_json]}
EOF
trap - ERR
echo "replicas: $replicas replicas behind nginx: REST http://127.0.0.1:$rest_port, gRPC 127.0.0.1:$grpc_port ($dir/endpoints.json)"
