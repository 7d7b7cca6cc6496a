# The two set-up commands of the README (`make demo`, `make test`) and the developer targets.
# Every target installs missing Debian packages first (scripts/install-deps.sh; instant when
# everything is present) and builds in $(BUILD_DIR).

BUILD_DIR ?= build
BUILD_TYPE ?= Release
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=

.PHONY: all deps configure build test demo bench fuzz sanitize container install clean train-correspondence-filter train-place-recognition

all: build

deps:
	@bash scripts/install-deps.sh

configure: deps
	@cmake -S . -B $(BUILD_DIR) -G Ninja -DCMAKE_BUILD_TYPE=$(BUILD_TYPE) -DPython_EXECUTABLE=/usr/bin/python3 $(CMAKE_FLAGS) > $(BUILD_DIR).configure.log 2>&1 \
		|| { cat $(BUILD_DIR).configure.log; exit 1; }

build: configure
	@cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	ctest --test-dir $(BUILD_DIR) --output-on-failure -j $(JOBS)

demo: build
	@bash scripts/demo.sh $(BUILD_DIR)

# The learned correspondence filter's weights (models/trained/correspondence_filter.json) from
# simulated camera images (models/trained/train_correspondence_filter.py; about 20 minutes).
train-correspondence-filter: build
	@/usr/bin/python3 models/trained/train_correspondence_filter.py --cli $(BUILD_DIR)/apps/hanzo-fusion \
		--work $(BUILD_DIR)/train-correspondence-filter --out models/trained/correspondence_filter.json

train-place-recognition: build
	@bash models/trained/place_recognition/train.sh $(BUILD_DIR)/apps/hanzo-fusion $(BUILD_DIR)/train-place-recognition \
		models/trained/vlad_aliked-t16.hzvlad

bench: build
	@bash scripts/bench.sh $(BUILD_DIR)

# libFuzzer (clang + AddressSanitizer) on the JSON and protobuf decoders, FUZZ_SECONDS each.
fuzz: deps
	@bash scripts/fuzz.sh $(BUILD_DIR)-fuzz

# The tests under AddressSanitizer + UndefinedBehaviorSanitizer, the service and pipeline tests
# under ThreadSanitizer ($(BUILD_DIR)-asan, $(BUILD_DIR)-tsan; about three hours on 2 cores).
sanitize: deps
	@bash scripts/sanitize.sh $(BUILD_DIR)

# The server image (Dockerfile) built with Debian's podman, then run and checked over REST and
# gRPC (scripts/container.sh; a full compile inside the image: about 15 minutes on 2 cores).
container: build
	@bash scripts/container.sh $(BUILD_DIR)

install: build
	cmake --install $(BUILD_DIR) $(if $(PREFIX),--prefix $(PREFIX),)

clean:
	rm -rf $(BUILD_DIR) $(BUILD_DIR).configure.log
