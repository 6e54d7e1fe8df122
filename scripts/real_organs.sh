# The real organs the sweeps plan (a source file, not a command): the kidneys, a vertebra
# and the liver grown from seeds on ct-crlm-1004 (5 mm slices; the seed in patient
# coordinates, LPS mm, grown within the HU window inside a cube of that side), and the GTVs
# of ct-sts-002 and ct-sts-004 imported from their structure sets (3.27 mm slices).
#   real_organ_sections NAME DATA_DIR   prints the scene's ct and organ sections
real_organ_sections() {
  local name=$1 data=$2 seed low high box
  case "$name" in
    kidney_left) seed="66.6, 29.2, -303.7" low=150 high=400 box=140 ;;
    kidney_right) seed="-58.8, 3.7, -326" low=150 high=400 box=140 ;;
    vertebra) seed="-3.3, 37.0, -272.5" low=150 high=400 box=160 ;;
    liver) seed="-86.6, -28.7, -275" low=95 high=165 box=260 ;;
    gtv_sts002 | gtv_sts004)
      local folder="$data/ct-sts-00${name: -1}"
      printf 'ct:\n  folder: %s\norgan:\n  rtstruct: %s\n  roi: GTV_Mass_CT\n' "$folder/ct" \
        "$folder/rtstruct.dcm"
      return ;;
    *) echo "real_organ_sections: no organ '$name'" >&2; return 2 ;;
  esac
  printf 'ct:\n  folder: %s\norgan:\n  source: seed\n  roi: %s\n  seed_mm: [%s]\n  hu_low: %s\n  hu_high: %s\n  search_box_mm: %s\n' \
    "$data/ct-crlm-1004/ct" "$name" "$seed" "$low" "$high" "$box"
}
