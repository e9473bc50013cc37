"""Bad input -> 422 naming the field, nothing written; tokens and ownership."""

from __future__ import annotations

import json

import pytest
from svc_helpers import auth, toy_spec, wait_done


def _nothing_written(service):
    assert service.http.get("/jobs", headers=auth("alice")).json() == []
    stores = service.settings.stores_dir
    assert not stores.exists() or not any(stores.iterdir())


def _bad(**patch):
    s = toy_spec(n=50)
    for path, value in patch.items():
        node = s
        keys = path.split("__")
        for k in keys[:-1]:
            node = node[k]
        node[keys[-1]] = value
    return s


one_cycle = toy_spec()["gaw"]["areas"][:30]

CASES = [
    (
        "nan_area",
        lambda: json.dumps(toy_spec()).replace("[0.0,", "[NaN,", 1).replace('"areas": [', '"areas": [NaN, ', 1),
        "areas",
    ),
    ("inf_area", lambda: json.dumps(toy_spec()).replace('"areas": [', '"areas": [Infinity, ', 1), "areas"),
    ("negative_area", lambda: _bad(gaw__areas=[-50.0] + toy_spec()["gaw"]["areas"]), "areas"),
    ("one_cycle", lambda: _bad(gaw__areas=one_cycle), "gaw"),
    ("fps_zero", lambda: _bad(gaw__fps=0), "fps"),
    ("fps_negative", lambda: _bad(gaw__fps=-4000), "fps"),
    ("lo_ge_hi", lambda: _bad(priors={"E_cover": [900.0, 400.0]}), "priors"),
    ("unknown_param", lambda: _bad(priors={"E_spine": [1.0, 2.0]}), "priors"),
    ("unknown_fixed", lambda: _bad(fixed={"bogus": 1.0}), "fixed"),
    ("negative_samples", lambda: _bad(sampler={"kind": "is", "n_samples": -5}), "n_samples"),
    ("absurd_samples", lambda: _bad(sampler={"kind": "is", "n_samples": 10**12}), "n_samples"),
    ("unknown_sampler", lambda: _bad(sampler={"kind": "mcmc", "n_samples": 5}), "sampler"),
    ("sigma_zero", lambda: _bad(sigma_e=0), "sigma_e"),
    ("unknown_noise_model", lambda: _bad(noise="student"), "noise"),
    ("sigma_bounds_reversed", lambda: _bad(noise="marginal", sigma_bounds=[2.0, 0.5]), "sigma_bounds"),
    ("negative_seed", lambda: _bad(seed=-1), "seed"),
    ("bad_mesh", lambda: _bad(mesh="huge"), "mesh"),
    ("unknown_contact", lambda: _bad(contact="rigid"), "contact"),
    ("contact_layer_too_thick", lambda: _bad(contact="layer", contact_layer_mm=1.0), "contact_layer_mm"),
    ("unknown_field", lambda: _bad(colour="red"), "colour"),
    ("wrong_units", lambda: _bad(gaw__units="px"), "units"),
    ("prior_outside_domain", lambda: _bad(priors={"x0": [7.0, 9.5]}, fixed={}), "priors"),
    ("measurement_unknown_param", lambda: _bad(measurements={"p_subglottal": [1000.0, 50.0]}), "measurements"),
    ("measurement_sd_zero", lambda: _bad(measurements={"p_sub": [1000.0, 0.0]}), "measurements"),
    ("measurement_sd_negative", lambda: _bad(measurements={"p_sub": [1000.0, -50.0]}), "measurements"),
    ("measurement_not_a_pair", lambda: _bad(measurements={"p_sub": [1000.0]}), "measurements"),
    ("measurement_infinite", lambda: json.dumps(_bad(measurements={"p_sub": [1000.0, 1e400]})), "measurements"),
    ("measurement_of_fixed", lambda: _bad(measurements={"rho": [1051.0, 10.0]}), "measurements"),
    ("malformed_json", lambda: '{"gaw": {"areas": [1, 2,', "json"),
    ("missing_gaw", lambda: {k: v for k, v in toy_spec().items() if k != "gaw"}, "gaw"),
]


@pytest.mark.parametrize("name,make,field", CASES, ids=[c[0] for c in CASES])
def test_bad_input_422_names_field(service, name, make, field):
    body = make()
    if isinstance(body, dict):
        body = json.dumps(body)
    r = service.http.post("/jobs", content=body, headers={**auth("alice"), "Content-Type": "application/json"})
    assert r.status_code == 422, (name, r.status_code, r.text[:300])
    assert field in r.text, r.text[:500]
    _nothing_written(service)


def test_toy_model_refused_when_disabled(service):
    service.settings.allow_toy_model = False
    try:
        r = service.http.post("/jobs", json=toy_spec(), headers=auth("alice"))
    finally:
        service.settings.allow_toy_model = True
    assert r.status_code == 422 and "model" in r.text
    _nothing_written(service)


def test_body_too_large_413(service):
    big = toy_spec()
    big["gaw"]["areas"] = big["gaw"]["areas"] * 1500  # > 2 MB (the test limit)
    r = service.http.post("/jobs", json=big, headers=auth("alice"))
    assert r.status_code == 413
    _nothing_written(service)


def test_tokens_and_ownership(service):
    http = service.http
    spec = toy_spec(n=60)
    assert http.post("/jobs", json=spec).status_code == 401
    assert http.post("/jobs", json=spec, headers={"Authorization": "Bearer nope-nope-nope"}).status_code == 401
    assert http.post("/jobs", json=spec, headers={"Authorization": "Basic YWxpY2U6eA=="}).status_code == 401
    _nothing_written(service)
    jid = http.post("/jobs", json=spec, headers=auth("alice")).json()["id"]
    wait_done(http, jid, "alice")
    for method, url in (
        ("GET", f"/jobs/{jid}"),
        ("GET", f"/jobs/{jid}/posterior"),
        ("GET", f"/jobs/{jid}/samples"),
        ("GET", f"/jobs/{jid}/figures/corner"),
        ("DELETE", f"/jobs/{jid}"),
    ):
        assert http.request(method, url).status_code == 401
        r = http.request(method, url, headers=auth("bob"))
        assert r.status_code == 404, (method, url, r.status_code)
        assert jid not in r.text
    assert http.get("/jobs", headers=auth("bob")).json() == []
    assert http.get("/jobs", headers=auth("alice")).json()[0]["state"] == "done"
    # ids are unguessable and never used as paths
    # "%2E%2E", not "..": the client resolves "/jobs/.." to "/" (the jobs page) before sending it
    for probe in ("%2E%2E", "..%2F..%2Fetc%2Fpasswd", "x" * 32, jid[:-1] + ("A" if jid[-1] != "A" else "B")):
        assert http.get(f"/jobs/{probe}", headers=auth("alice")).status_code == 404
    assert http.get(f"/jobs/{jid}/figures/jobs.sqlite", headers=auth("alice")).status_code == 422
    assert http.get(f"/jobs/{jid}/samples", params={"format": "pickle"}, headers=auth("alice")).status_code == 422
