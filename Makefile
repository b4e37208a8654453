# clipmap — plain Makefile, out-of-tree objects in build/ (BUILD=... for variants).
#   make            build everything
#   make check      install deps, build, run every test
#   make asan/tsan  the same suite under sanitizers (build-asan/, build-tsan/)
#   make bench      benchmarks that print figures
#   make deps       install the Debian packages the project needs (and prepare data/)
#   make data       install the planet data packages and import them into data/

BUILD   ?= build
CC      ?= cc
CXX     ?= g++
PKGS    := OpenImageIO geographiclib libxxhash libzstd liblz4 libsystemd gdal
PKG_CFLAGS := $(shell pkg-config --cflags $(PKGS) 2>/dev/null)
PKG_LIBS   := $(shell pkg-config --libs $(PKGS) 2>/dev/null)

OPT     ?= -O2 -g
WARN    := -Wall -Wextra -Wshadow -Wstrict-prototypes -Wmissing-prototypes -Wformat=2 -Wvla \
           -fno-common -Werror
CFLAGS  += -std=c11 -D_GNU_SOURCE $(OPT) $(WARN) -pthread -MMD -MP -iquote common -iquote daemon -iquote client \
           $(SAN)
CXXFLAGS += -std=c++17 $(OPT) -Wall -Wextra -Werror -fPIC -pthread -MMD -MP -iquote common $(SAN) \
           $(filter-out -I/usr/include,$(PKG_CFLAGS))
LDFLAGS += -pthread $(SAN)
LDLIBS  += $(PKG_LIBS) -lcmocka -lstdc++ -lm

# Per-ISA kernels: files named *_avx2.c / *_avx512.c get their -m flags (run-time dispatch).
AVX2_FLAGS   := -mavx2 -mfma -mbmi2
AVX512_FLAGS := -mavx512f -mavx512dq -mavx512bw -mavx512vl -mavx2 -mfma -mbmi2

# Every main() lives in its own file; all other sources form the library the tests link.
MAINS        := daemon/clipmapd.c client/clipmapctl.c
COMMON_SRC   := $(wildcard common/*.c)
COMMON_CXX   := $(wildcard common/*.cpp)
DAEMON_SRC   := $(filter-out $(MAINS),$(wildcard daemon/*.c))
CLIENT_SRC   := $(filter-out $(MAINS) client/gl_%.c client/view%.c,$(wildcard client/*.c))
LIB_SRC      := $(COMMON_SRC) $(DAEMON_SRC) $(CLIENT_SRC)
LIB_OBJ      := $(LIB_SRC:%.c=$(BUILD)/%.o) $(COMMON_CXX:%.cpp=$(BUILD)/%.o)
LIB          := $(BUILD)/libclipmap.a

UNIT_SRC     := $(wildcard tests/unit/test_*.c)
UNIT_BIN     := $(UNIT_SRC:tests/unit/%.c=$(BUILD)/tests/%)
BENCH_SRC    := $(wildcard tests/bench/bench_*.c)
BENCH_BIN    := $(BENCH_SRC:tests/bench/%.c=$(BUILD)/tests/%)
PROGS        := $(foreach m,$(MAINS),$(if $(wildcard $(m)),$(BUILD)/$(notdir $(basename $(m)))))

.PHONY: all check test asan tsan bench deps clean demo data
.SECONDARY:
all: $(PROGS) $(UNIT_BIN) $(BENCH_BIN)

$(BUILD)/%.o: %.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -c $< -o $@
$(BUILD)/%_avx2.o: %_avx2.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(AVX2_FLAGS) -c $< -o $@
$(BUILD)/%_avx512.o: %_avx512.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(AVX512_FLAGS) -c $< -o $@
$(BUILD)/%.o: %.cpp
	@mkdir -p $(dir $@)
	$(CXX) $(CXXFLAGS) -c $< -o $@

$(LIB): $(LIB_OBJ)
	@rm -f $@
	ar rcs $@ $^

$(BUILD)/clipmapd: $(BUILD)/daemon/clipmapd.o $(LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS) -o $@
$(BUILD)/clipmapctl: $(BUILD)/client/clipmapctl.o $(LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS) -o $@
$(BUILD)/tests/%: $(BUILD)/tests/unit/%.o $(LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $^ $(LDLIBS) -o $@
$(BUILD)/tests/bench_%: $(BUILD)/tests/bench/bench_%.o $(LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $^ $(LDLIBS) -o $@

deps:
	@sh scripts/deps.sh

# Planet data (Debian packages) imported into data/ (gitignored); deps runs it too.
data:
	@BUILD=$(BUILD) sh scripts/data.sh

check: deps
	@$(MAKE) --no-print-directory all
	@sh tests/run.sh $(BUILD)

test: all
	@sh tests/run.sh $(BUILD)

asan: export ASAN_OPTIONS = detect_leaks=1:abort_on_error=0
asan: export LSAN_OPTIONS = suppressions=$(CURDIR)/tests/lsan.supp:print_suppressions=0
asan: export UBSAN_OPTIONS = print_stacktrace=1:halt_on_error=1
asan:
	@$(MAKE) --no-print-directory BUILD=build-asan OPT="-O1 -g" \
	  SAN="-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all" test

tsan: export TSAN_OPTIONS = suppressions=$(CURDIR)/tests/tsan.supp:halt_on_error=1:second_deadlock_stack=1
tsan:
	@$(MAKE) --no-print-directory BUILD=build-tsan OPT="-O1 -g" SAN="-fsanitize=thread" test

bench: deps
	@$(MAKE) --no-print-directory all
	@sh tests/bench/run.sh $(BUILD)

demo: deps
	@$(MAKE) --no-print-directory all
	@sh scripts/demo.sh $(BUILD)

clean:
	rm -rf build build-asan build-tsan

-include $(shell find $(BUILD) -name '*.d' 2>/dev/null)
