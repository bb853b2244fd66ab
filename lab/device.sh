# Sourced at the start of a command on the lent GPU machine (the `device` tool), from the repo root:
#   source lab/device.sh
# It sets up OpenGL (../shared/gpu/prepare.sh's .gl and .whl, carried), makes the app/ folder
# importable as `radiance_probes`, unpacks carried datasets (.data/*.gz) where the bench scenes look
# for them, and puts Open Image Denoise on the path once it is assembled in /tmp/devcache/oidn (see
# lab/README.md: the library is larger than one call may carry, so it travels in parts).
source .gl/on-device.sh
mkdir -p /tmp/pkg && ln -sfn "$PWD/app" /tmp/pkg/radiance_probes
export PYTHONPATH=/tmp/pkg:$PYTHONPATH
mkdir -p ../shared/datasets /tmp/devcache
for f in .data/*.gz; do
  [ -f "$f" ] || continue
  raw=../shared/datasets/$(basename "$f" .gz)
  [ -f "$raw" ] || gunzip -c "$f" > "$raw"
done
for f in .data/*.nrrd; do [ -f "$f" ] && cp -n "$f" ../shared/datasets/; done
# The library travels in parts, one a call (each call's tree must stay under 64 MiB): call k
# carries .oidnqk (k = 1 .. OIDN_PARTS, made by `split -n OIDN_PARTS -d .oidn/pyoidn.tgz`; the last
# also with pyoidn's wheels, cffi and pycparser) and copies it to /tmp/devcache; the call that
# finds all parts assembles them.
OIDN_PARTS=2
for i in $(seq 1 $OIDN_PARTS); do [ -f .oidnq$i/part ] && cp .oidnq$i/part /tmp/devcache/oidn.q$i; done
cp .oidnq$OIDN_PARTS/*.whl /tmp/devcache/ 2>/dev/null
have=0
for i in $(seq 1 $OIDN_PARTS); do [ -f /tmp/devcache/oidn.q$i ] && have=$((have + 1)); done
if [ ! -d /tmp/devcache/oidn/pyoidn ] && [ $have -eq $OIDN_PARTS ]; then
  mkdir -p /tmp/devcache/oidn
  for i in $(seq 1 $OIDN_PARTS); do cat /tmp/devcache/oidn.q$i; done | tar xz -C /tmp/devcache/oidn
  (cd /tmp/devcache/oidn/pyoidn/oidn/lib && ln -sf libOpenImageDenoise.so.2 libOpenImageDenoise.so \
    && ln -sf libOpenImageDenoise.so.2 "libOpenImageDenoise.so.$(ls libOpenImageDenoise_core.so.* | sed 's/.*core\.so\.//')")
  python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/devcache/oidn /tmp/devcache/*.whl
fi
[ -d /tmp/devcache/oidn/pyoidn ] && export PYTHONPATH=/tmp/devcache/oidn:$PYTHONPATH
true
