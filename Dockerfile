# One image for the Dask scheduler, the Dask workers and the API (see docker-compose.yml).
# Not built in CI (no Docker engine there); see docs/service.md.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    OMP_NUM_THREADS=1 \
    OPENBLAS_NUM_THREADS=1 \
    MKL_NUM_THREADS=1 \
    NUMBA_NUM_THREADS=1 \
    MPLBACKEND=Agg \
    PYTHONPATH=/app

WORKDIR /app
# dependencies first (layer cache): exactly the committed lock, hashes checked, as `make install` does
COPY requirements.lock ./
RUN pip install --require-hashes --no-deps -r requirements.lock
COPY pyproject.toml README.md ./
COPY vfcore ./vfcore
COPY vfvideo ./vfvideo
COPY worker ./worker
COPY service ./service
RUN pip install --no-deps --no-build-isolation . \
    && useradd --create-home --uid 1000 vf \
    && mkdir -p /data && chown vf:vf /data
USER vf
# numba caches compiled kernels here (a writable place for the non-root user)
ENV NUMBA_CACHE_DIR=/tmp/numba-cache

EXPOSE 8000 8786 8787
CMD ["vfinfer", "serve", "--host", "0.0.0.0", "--port", "8000"]
