# The hanzo-fusion server image: Debian 12, built from source in a builder stage, run by a
# non-root user; REST on 8083, gRPC on 8084, health check on /v1/health (docs/container.md).
# BASE is a Debian 12 image: debian:bookworm from a registry, or the local root that
# scripts/container.sh makes with debootstrap where no registry is reachable.
ARG BASE=debian:bookworm

FROM ${BASE} AS build
ENV DEBIAN_FRONTEND=noninteractive
# The server's build dependencies (scripts/install-deps.sh without the tests', benchmarks',
# Python's and the learned module's packages).
RUN apt-get update && apt-get install -y --no-install-recommends \
      build-essential cmake ninja-build pkg-config \
      libeigen3-dev libgeographiclib-dev libyaml-cpp-dev libspdlog-dev libfmt-dev nlohmann-json3-dev \
      libprotobuf-dev protobuf-compiler libgrpc++-dev protobuf-compiler-grpc \
      libzstd-dev liblz4-dev zlib1g-dev libbz2-dev libssl-dev libopencv-dev libsodium-dev libcurl4-openssl-dev \
      libtbb-dev libceres-dev libopenblas0-pthread libpcl-dev libnanoflann-dev libabsl-dev libcli11-dev \
      libcpp-httplib-dev libbrotli-dev libsqlite3-dev libpq-dev libpqxx-dev libjwt-dev \
    && rm -rf /var/lib/apt/lists/*
WORKDIR /src
# The source with web/node_modules (the viewer's bundler; scripts/install-deps.sh installs it).
COPY . .
RUN cmake -S . -B /build -G Ninja -DCMAKE_BUILD_TYPE=Release -DPython_EXECUTABLE=/usr/bin/python3 \
      -DHANZO_BUILD_TESTS=OFF -DHANZO_BUILD_BENCHMARKS=OFF -DHANZO_BUILD_PYTHON=OFF -DHANZO_FUSION_AI=OFF -DHANZO_FUSION_CUDA=OFF \
    && cmake --build /build --target hanzo-fusion \
    && strip /build/apps/hanzo-fusion
# The runtime image needs the packages that own the program's shared libraries.
RUN for library in $(ldd /build/apps/hanzo-fusion | awk '/=> \//{print $3}'); do \
      dpkg -S "$library" 2>/dev/null || dpkg -S "$(readlink -f "$library")" 2>/dev/null || dpkg -S "/usr$library" 2>/dev/null; \
    done | cut -d: -f1 | sort -u > /runtime-packages.txt \
    && test -s /runtime-packages.txt

FROM ${BASE}
ENV DEBIAN_FRONTEND=noninteractive
COPY --from=build /runtime-packages.txt /tmp/runtime-packages.txt
RUN apt-get update && xargs -a /tmp/runtime-packages.txt apt-get install -y --no-install-recommends ca-certificates curl opencv-data \
    && rm -rf /var/lib/apt/lists/* /tmp/runtime-packages.txt \
    && useradd --system --create-home --home-dir /var/lib/hanzo-fusion --shell /usr/sbin/nologin fusion
COPY --from=build /build/apps/hanzo-fusion /usr/local/bin/hanzo-fusion
USER fusion
WORKDIR /var/lib/hanzo-fusion
EXPOSE 8083 8084
HEALTHCHECK --interval=30s --timeout=5s --start-period=10s CMD curl -fsS http://127.0.0.1:8083/v1/health || exit 1
ENTRYPOINT ["hanzo-fusion", "serve"]
CMD ["--data-dir", "/var/lib/hanzo-fusion/data"]
