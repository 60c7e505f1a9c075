# shots.mk: a reusable GNU make fragment that turns USD shots into camtraj robot moves.
#
# Set any of the variables below (or on the make command line), then `include shots.mk`:
#
#   SHOTS_DIR = shots          folder of the USD shots (*.usd *.usda *.usdc *.usdz)
#   OUT       = out            folder for NAME.mcap and NAME.summary.json
#   EXCLUDE   = NAME ...       shot names (file names without extension) to leave out
#   CAMTRAJ   = camtraj        the camtraj command
#   ROBOT     = robot.toml     robot description (outputs also depend on this file)
#   SET_FILE  = set.toml       set file: the track's layout on set, obstacles (`camtraj place`
#                              writes one; outputs also depend on this file)
#   LENS      = lens.toml      lens file: zoom, focus and iris motors (outputs also depend on it)
#   PLACEMENT = x,y,z,yaw_deg  stage-to-robot placement
#   TIMING    = shot           shot | scale | optimal
#   RATE      = 250            servo rate [Hz] (empty: camtraj's default)
#   FRAMES    = A:B            film frame range (empty: the whole shot)
#   CAMERA    = /World/cam     camera prim (empty: the only camera)
#   CAMTRAJ_FLAGS = --quiet    anything else to pass to camtraj convert / check
#
# Targets: all (every NAME.mcap), check (camtraj check on every shot), clean, and the same as
# camtraj-all, camtraj-check, camtraj-clean for Makefiles that have their own all/check/clean
# recipes (set CAMTRAJ_NO_DEFAULT_TARGETS = 1 to leave all/check/clean alone).
#
# Incremental: OUT/NAME.mcap is remade when the shot, the robot, set or lens file or the convert
# options change (a file passed in CAMTRAJ_FLAGS is not watched: use the variables); use `make -k -jN` to convert in parallel and go on past shots that fail. A failed
# shot leaves neither NAME.mcap (camtraj writes atomically) nor a stale NAME.summary.json.
# Shot file names must not contain spaces (a make limitation: use `camtraj batch` for those).

CAMTRAJ       ?= camtraj
SHOTS_DIR     ?= shots
OUT           ?= out
EXCLUDE       ?=
ROBOT         ?=
SET_FILE      ?=
LENS          ?=
PLACEMENT     ?=
TIMING        ?= shot
RATE          ?=
FRAMES        ?=
CAMERA        ?=
CAMTRAJ_FLAGS ?=

CAMTRAJ_SHOT_EXTS := usd usda usdc usdz
CAMTRAJ_SHOTS := $(sort $(foreach e,$(CAMTRAJ_SHOT_EXTS),$(wildcard $(SHOTS_DIR)/*.$(e))))
CAMTRAJ_NAMES := $(filter-out $(EXCLUDE),$(sort $(basename $(notdir $(CAMTRAJ_SHOTS)))))
CAMTRAJ_MCAPS := $(CAMTRAJ_NAMES:%=$(OUT)/%.mcap)
CAMTRAJ_SUMMARIES := $(CAMTRAJ_NAMES:%=$(OUT)/%.summary.json)
CAMTRAJ_CHECKS := $(CAMTRAJ_NAMES:%=camtraj-check/%)

# Options shared by convert and check.
CAMTRAJ_OPTIONS := $(strip \
  $(if $(CAMERA),--camera $(CAMERA)) \
  $(if $(ROBOT),--robot $(ROBOT)) \
  $(if $(SET_FILE),--set-file $(SET_FILE)) \
  $(if $(LENS),--lens $(LENS)) \
  $(if $(PLACEMENT),--placement $(PLACEMENT)) \
  $(if $(FRAMES),--frames $(FRAMES)) \
  $(if $(RATE),--rate $(RATE)) \
  $(if $(TIMING),--timing $(TIMING)) \
  $(CAMTRAJ_FLAGS))

# The files every conversion reads besides its shot: a change to one remakes every MCAP.
CAMTRAJ_FILES := $(ROBOT) $(SET_FILE) $(LENS)

# The options used last are kept in OUT/.camtraj-options; it is rewritten (at parse time, so
# `make -q` still answers correctly) only when they change, and every MCAP depends on it.
CAMTRAJ_OPTIONS_FILE := $(OUT)/.camtraj-options
ifneq ($(filter-out clean camtraj-clean check camtraj-check camtraj-check/%,$(or $(MAKECMDGOALS),all)),)
  ifneq ($(strip $(file <$(CAMTRAJ_OPTIONS_FILE))),$(CAMTRAJ_OPTIONS))
    $(shell mkdir -p '$(OUT)')
    $(file >$(CAMTRAJ_OPTIONS_FILE),$(CAMTRAJ_OPTIONS))
  endif
endif

# Delete a target whose recipe failed after touching it (this applies to the including
# Makefile's rules too, as the GNU make manual recommends for every Makefile).
.DELETE_ON_ERROR:

.PHONY: camtraj-all camtraj-check camtraj-clean $(CAMTRAJ_CHECKS)

ifeq ($(CAMTRAJ_NO_DEFAULT_TARGETS),)
.PHONY: all check clean
all: camtraj-all
check: camtraj-check
clean: camtraj-clean
endif

camtraj-all: $(CAMTRAJ_MCAPS)

camtraj-check: $(CAMTRAJ_CHECKS)

camtraj-clean:
	rm -f $(CAMTRAJ_MCAPS) $(CAMTRAJ_SUMMARIES) $(CAMTRAJ_OPTIONS_FILE)
	-rmdir $(OUT) 2>/dev/null || true

$(OUT):
	mkdir -p $@

# Written by the parse-time code above; this rule only recreates it after a `make clean all`.
$(CAMTRAJ_OPTIONS_FILE): | $(OUT)
	$(file >$@,$(CAMTRAJ_OPTIONS))

# One conversion; $< is the shot. Old outputs go first, and a failed run removes what it wrote,
# so a shot that fails leaves neither an MCAP nor a summary behind; the recipe exits with
# camtraj's own code (2 bad input, 3 cannot be done, 130 interrupted: make says "Error 3").
define camtraj-convert
	@rm -f $@ $(@:.mcap=.summary.json)
	$(CAMTRAJ) convert $< -o $@ --summary $(@:.mcap=.summary.json) $(CAMTRAJ_OPTIONS) \
	  || { code=$$?; rm -f $@ $(@:.mcap=.summary.json); exit $$code; }
endef

$(OUT)/%.mcap: $(SHOTS_DIR)/%.usda $(CAMTRAJ_FILES) $(CAMTRAJ_OPTIONS_FILE) | $(OUT)
	$(camtraj-convert)
$(OUT)/%.mcap: $(SHOTS_DIR)/%.usd $(CAMTRAJ_FILES) $(CAMTRAJ_OPTIONS_FILE) | $(OUT)
	$(camtraj-convert)
$(OUT)/%.mcap: $(SHOTS_DIR)/%.usdc $(CAMTRAJ_FILES) $(CAMTRAJ_OPTIONS_FILE) | $(OUT)
	$(camtraj-convert)
$(OUT)/%.mcap: $(SHOTS_DIR)/%.usdz $(CAMTRAJ_FILES) $(CAMTRAJ_OPTIONS_FILE) | $(OUT)
	$(camtraj-convert)

# `make check`: analysis only, no output files; -k goes on past failing shots.
$(CAMTRAJ_CHECKS): camtraj-check/%:
	$(CAMTRAJ) check $(firstword $(filter $(CAMTRAJ_SHOT_EXTS:%=$(SHOTS_DIR)/$*.%),$(CAMTRAJ_SHOTS))) $(CAMTRAJ_OPTIONS)
