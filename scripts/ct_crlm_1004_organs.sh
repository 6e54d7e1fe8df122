# The organs the sweeps grow from seeds on ../shared/data/ct-crlm-1004 (5 mm slices; a
# source file, not a command): NAME|SEED_MM|HU_LOW|HU_HIGH|SEARCH_BOX_MM, the seed in
# patient coordinates (LPS, mm), grown within the HU window inside a cube of that side.
# shellcheck disable=SC2034
ct_crlm_1004_organs=(
  "kidney_left|66.6, 29.2, -303.7|150|400|140"
  "kidney_right|-58.8, 3.7, -326|150|400|140"
  "vertebra|-3.3, 37.0, -272.5|150|400|160"
  "liver|-86.6, -28.7, -275|95|165|260"
)
