/* Surface scattering as Cycles' Principled BSDF builds it (and the Glossy
 * and Glass shader nodes, as one-lobe cases), every path-following kernel
 * sharing it:
 *   metal        weight metallic: GGX reflection, F82-tint Fresnel from the
 *                base colour (Glossy node: Fresnel = its colour);
 *   glass        weight (1 - metallic) transmission: GGX reflection and
 *                refraction by the dielectric Fresnel remapped to the
 *                tinted F0, refraction tinted by sqrt(base colour) (Glass
 *                node: F0 untinted, both tinted by its colour);
 *   specular     weight (1 - metallic)(1 - transmission): a dielectric GGX
 *                reflection of index eta' (Specular IOR Level) over
 *   diffuse      Lambert, base colour x that weight x what the specular
 *                layer leaves (1 - its directional albedo).
 * All share alpha = roughness^2 (metal and specular stretched to alpha_x,
 * alpha_y along a tangent where anisotropic); every lobe gets Multiscatter
 * GGX's energy (microfacet.h; glass by its own albedo tables); at alpha^2
 * <= MICROFACET_SINGULAR_ALPHA2 a lobe is a perfect mirror or smooth glass
 * (sampled only, never evaluated). Directions are local to the shading
 * normal's frame, wo towards the viewer; the glossy lobes work in a frame
 * of their own where it differs (raised normal, anisotropic tangent).
 * Sampling picks one lobe by its estimated albedo and weighs a smooth
 * direction by the whole BSDF over the mixture pdf. */
#ifndef GPUGI_BSDF_H
#define GPUGI_BSDF_H
#include "device/structs.h"
#include "shading/microfacet.h"

#define BSDF_DIFFUSE 0
#define BSDF_SPECULAR 1
#define BSDF_METAL 2
#define BSDF_GLASS 3
#define BSDF_LOBES 4

/* labels of a sampled direction */
#define BSDF_LABEL_DIFFUSE 1
#define BSDF_LABEL_GLOSSY 2
#define BSDF_LABEL_SINGULAR 4
#define BSDF_LABEL_TRANSMIT 8

/* which lobes sampling may choose (all are evaluated) */
#define BSDF_SAMPLE_DIFFUSE 1
#define BSDF_SAMPLE_GLOSSY 2 /* every lobe but the diffuse one */
#define BSDF_SAMPLE_ALL 3

typedef struct {
    float3 t, b, n;       /* shading frame (the diffuse lobe's), n on the viewer's side of the surface */
    float3 wo, ng;        /* local: towards the viewer, geometric normal on its side */
    float3 gt, gb, gn;    /* the glossy lobes' frame: n raised towards ng where the view's mirror
                             direction would go below the surface (Cycles' valid specular reflection) */
    float3 gwo;           /* the view in the glossy frame */
    bool split;           /* the glossy frame is not the shading frame */
    bool aniso;           /* metal and specular lobes stretched: alpha ax along gt, ay along gb */
    float ax, ay;
    float3 smooth;        /* local: the normal before a normal map, on the viewer's side */
    bool mapped;          /* a normal map moved the shading normal off the smooth one */
    float rough, alpha2;
    bool singular;
    float3 diffuse;       /* the diffuse lobe's albedo (weights and layering applied) */
    float on_a, on_b;     /* Oren-Nayar's A and B (B = 0: Lambert) */
    float3 on_ms;         /* and its multiple-scattering term for this view */
    float w_specular, w_metal, w_glass;
    float spec_eta;
    float3 spec_f0, spec_ms;
    float3 metal_f0, metal_b, metal_ms;
    bool metal_constant;  /* Glossy node: Fresnel = metal_f0 */
    float glass_eta;      /* n_t / n_i on this side */
    float3 glass_f0, glass_rtint, glass_ttint, glass_ms;
    float q[BSDF_LOBES];  /* probability of sampling each lobe */
    int sample;           /* the lobes sampling may choose (BSDF_SAMPLE_*) */
} Bsdf;

inline float Bsdf_avg(float3 c) { return (c.x + c.y + c.z) * (1.0f / 3.0f); }

inline float3 Bsdf_reflect(float3 d, float3 n) { return d - 2.0f * dot(d, n) * n; }

inline float3 Bsdf_to_local(const Bsdf *f, float3 v) { return (float3)(dot(v, f->t), dot(v, f->b), dot(v, f->n)); }

inline float3 Bsdf_to_world(const Bsdf *f, float3 v) { return v.x * f->t + v.y * f->b + v.z * f->n; }

/* A local direction in the glossy frame, and back. */
inline float3 Bsdf_to_glossy(const Bsdf *f, float3 v) {
    if (!f->split) return v;
    float3 w = Bsdf_to_world(f, v);
    return (float3)(dot(w, f->gt), dot(w, f->gb), dot(w, f->gn));
}

inline float3 Bsdf_from_glossy(const Bsdf *f, float3 g) {
    return f->split ? Bsdf_to_local(f, g.x * f->gt + g.y * f->gb + g.z * f->gn) : g;
}

/* The normal of the glossy lobes for the view wo (world, all on the view's
 * side): n itself where the mirror direction of wo leaves the surface by
 * at least min(0.9 cos, 0.01) of ng, else n turned towards ng in their
 * plane just enough for that, as Cycles' ensure_valid_specular_reflection
 * (a shading normal tilted away from the viewer, at silhouettes and under
 * normal maps, would reflect the view into the surface). */
inline float3 Bsdf_glossy_normal(float3 ng, float3 wo, float3 n) {
    float iz = dot(wo, ng);
    float threshold = fmin(0.9f * iz, 0.01f);
    if (dot(ng, 2.0f * dot(n, wo) * n - wo) >= threshold) return n;
    float3 x = n - dot(n, ng) * ng;
    float xl = length(x);
    x = xl > 1e-7f ? x / xl : n;
    float ix = dot(wo, x);
    float a = ix * ix + iz * iz;
    if (!(a > 0.0f)) return ng;
    float b = 2.0f * (a + iz * threshold), c = (threshold + iz) * (threshold + iz);
    float root = sqrt(fmax(b * b - 4.0f * a * c, 0.0f));
    float nz2 = clamp(0.25f * (ix < 0.0f ? b + root : b - root) / a, 0.0f, 1.0f);
    return normalize(sqrt(1.0f - nz2) * x + sqrt(nz2) * ng);
}

/* Fujii's improved Oren-Nayar, as Cycles' rough diffuse: the
 * directional albedo's angular part G(cos) (E(cos) = A pi + B G(cos)),
 * its series near grazing. */
inline float Bsdf_oren_nayar_G(float c) {
    if (c < 1e-6f) return (0.5f * PI_F - 2.0f / 3.0f) - c;
    float s = sqrt(fmax(1.0f - c * c, 0.0f)), theta = acos(clamp(c, -1.0f, 1.0f));
    return s * (theta - 2.0f / 3.0f - s * c) + (2.0f / 3.0f) * (s / c) * (1.0f - s * s * s);
}

/* The diffuse lobe's shape for the local light direction wi (wi.z > 0),
 * its albedo factored out: cos / pi (Lambert), or Oren-Nayar's
 * cos (A + B t) plus the multiple-scattering term OpenPBR adds to keep
 * its energy, (1 - E(cos)) times on_ms. */
inline float3 Bsdf_diffuse_shape(const Bsdf *f, float3 wi) {
    float nl = wi.z;
    if (!(f->on_b > 0.0f)) return (float3)(nl / PI_F);
    float nv = f->wo.z, t = dot(wi, f->wo) - nl * nv;
    if (t > 0.0f) t /= fmax(nl, nv) + FLT_MIN;
    float el = f->on_a * PI_F + f->on_b * Bsdf_oren_nayar_G(nl);
    return nl * ((float3)(f->on_a + f->on_b * t) + f->on_ms * (1.0f - el));
}

/* Metal Fresnel at cos to the microfacet normal. */
inline float3 Bsdf_metal_fresnel(const Bsdf *f, float cos_i) {
    return f->metal_constant ? f->metal_f0 : Microfacet_fresnel_f82(f->metal_f0, f->metal_b, cos_i);
}

/* Glass: reflected and transmitted parts of the Fresnel at cos to h, with
 * the multiple-scattering factor. */
inline void Bsdf_glass_fresnel(const Bsdf *f, float cos_i, float3 *r, float3 *t) {
    float3 fr = Microfacet_fresnel_remap(f->glass_f0, cos_i, f->glass_eta); /* 1 on total internal reflection */
    *r = fr * f->glass_rtint * f->glass_ms;
    *t = ((float3)(1.0f) - fr) * f->glass_ttint * f->glass_ms;
}

inline float Bsdf_reflect_probability(float3 r, float3 t) {
    float sum = Bsdf_avg(r + t);
    return sum > 0.0f ? Bsdf_avg(r) / sum : 1.0f;
}

/* The BSDF of material m (base: its colour, texture applied) seen from
 * direction wo_world (towards the viewer) at a surface with shading normal
 * ns, the normal before a normal map `smooth` (ns without one), geometric
 * normal ng (all on the viewer's side) and tangent (world; zero: none,
 * the lobes stay isotropic); `entering`: the viewer is outside the object
 * (by the wound normal). `sample`: the lobes sampling may choose
 * (BSDF_SAMPLE_*). */
inline Bsdf Bsdf_make(const Material *m, float3 base, float3 wo_world, float3 ns, float3 smooth, float3 ng,
                      float3 tangent, bool entering, int sample) {
    Bsdf f;
    f.sample = sample;
    f.rough = clamp(m->roughness, 0.0f, 1.0f);
    float alpha = f.rough * f.rough;
    f.alpha2 = alpha * alpha;
    f.singular = f.alpha2 <= MICROFACET_SINGULAR_ALPHA2;
    /* the diffuse lobe keeps the shading normal even where it faces away
     * from the viewer (as Cycles does); the glossy lobes get theirs */
    f.n = ns;
    Sampling_frame(f.n, &f.t, &f.b);
    f.wo = Bsdf_to_local(&f, wo_world);
    f.wo.z = fmax(f.wo.z, 1e-6f);
    f.gn = Bsdf_glossy_normal(ng, wo_world, ns);
    /* an anisotropic material turns the glossy frame to its tangent, itself
     * turned about the normal by the rotation (as Cycles) */
    f.aniso = !f.singular && m->aniso_x != m->aniso_y && dot(tangent, tangent) > 0.0f;
    if (f.aniso) {
        float turn = 2.0f * PI_F * m->aniso_rotation, c = cos(turn), s = sin(turn);
        float3 along = tangent * c + cross(ns, tangent) * s + ns * dot(ns, tangent) * (1.0f - c);
        float3 b = cross(f.gn, along);
        float bl = length(b);
        f.aniso = bl > 1e-6f;
        f.gb = b / bl;
        f.gt = cross(f.gb, f.gn);
    }
    f.ax = alpha * (f.aniso ? m->aniso_x : 1.0f);
    f.ay = alpha * (f.aniso ? m->aniso_y : 1.0f);
    f.split = f.aniso || dot(f.gn, ns) < 1.0f - 1e-6f;
    f.gwo = f.wo;
    if (f.split) {
        if (!f.aniso) Sampling_frame(f.gn, &f.gt, &f.gb);
        f.gwo = (float3)(dot(wo_world, f.gt), dot(wo_world, f.gb), fmax(dot(wo_world, f.gn), 1e-6f));
    }
    f.ng = Bsdf_to_local(&f, ng);
    f.smooth = Bsdf_to_local(&f, smooth);
    f.mapped = dot(ns, smooth) < 1.0f - 1e-6f;
    float mu = f.gwo.z; /* the glossy lobes' view angle */
    float metallic = clamp(m->metallic, 0.0f, 1.0f), transmission = clamp(m->transmission, 0.0f, 1.0f);
    float3 c = fmax(base, (float3)(0.0f)), cc = fmin(c, (float3)(1.0f));
    float3 tint = fmax(m->specular_tint.xyz, (float3)(0.0f));
    float3 one = (float3)(1.0f);
    /* a surface of a mix carries its weight over the chance it was picked with */
    float scale = m->mix_scale;
    f.w_metal = scale * metallic;
    f.w_glass = scale * (1.0f - metallic) * transmission;
    f.w_specular = scale * (1.0f - metallic) * (1.0f - transmission);
    /* metal */
    f.metal_constant = m->shader == MATERIAL_GLOSSY;
    f.metal_f0 = cc;
    float3 f_ss = cc;
    f.metal_b = (float3)(0.0f);
    if (!f.metal_constant) {
        /* B from the F82 tint: Schlick at mu = 1/7 times the tint */
        const float x = 6.0f / 7.0f, x5 = x * x * x * x * x;
        f.metal_b = mix(cc, one, x5) * (7.0f / (x5 * x)) * (one - fmin(tint, one));
        f_ss = mix(cc, one, 1.0f / 21.0f) - f.metal_b * (1.0f / 126.0f);
    }
    /* GGX (single_scatter) keeps only what single scattering reflects; Multiscatter GGX gives the rest back */
    f.metal_ms = f.w_metal > 0.0f && !m->single_scatter ? Microfacet_multiscatter(f.rough, mu, clamp(f_ss, 0.0f, 1.0f))
                                                         : one;
    /* glass */
    f.glass_eta = entering ? m->ior : 1.0f / m->ior;
    bool glass_node = m->shader == MATERIAL_GLASS;
    f.glass_f0 = fmin((float3)(Microfacet_f0(m->ior)) * (glass_node ? one : tint), one);
    f.glass_rtint = glass_node ? c : one;
    f.glass_ttint = glass_node ? c : sqrt(cc);
    f.glass_ms = f.w_glass > 0.0f && !m->single_scatter
                     ? Microfacet_glass_multiscatter(f.rough, mu, f.glass_eta, glass_node ? one : f.glass_ttint)
                     : one;
    /* the specular layer and what it leaves the diffuse base */
    f.spec_eta = m->specular_tint.w;
    f.spec_f0 = fmin((float3)(Microfacet_f0(f.spec_eta)) * tint, one);
    if (fabs(f.spec_eta - 1.0f) < 1e-5f) f.w_specular = 0.0f;
    f.spec_ms = one;
    float layer = 1.0f;
    if (f.w_specular > 0.0f) {
        f.spec_ms = m->single_scatter ? one : Microfacet_multiscatter(f.rough, mu, m->specular_fss.xyz);
        float3 albedo = Microfacet_E(f.rough, mu) * f.spec_ms * mix(f.spec_f0, one, Microfacet_S(f.rough, mu, f.spec_eta));
        layer = clamp(1.0f - fmax(fmax(albedo.x, albedo.y), albedo.z), 0.0f, 1.0f);
    }
    f.diffuse = m->shader == MATERIAL_PRINCIPLED ? c * (scale * (1.0f - metallic) * (1.0f - transmission) * layer)
                                                 : (float3)(0.0f);
    /* rough diffuse: Oren-Nayar's A, B and multiple scattering for this view (Cycles' constants) */
    float sigma = clamp(m->diffuse_roughness, 0.0f, 1.0f);
    f.on_a = 1.0f / PI_F;
    f.on_b = 0.0f;
    f.on_ms = (float3)(0.0f);
    if (sigma >= 1e-5f) {
        f.on_a = 1.0f / (PI_F + sigma * (0.5f * PI_F - 2.0f / 3.0f));
        f.on_b = sigma * f.on_a;
        float e_avg = f.on_a * PI_F + ((2.0f * PI_F - 5.6f) / 3.0f) * f.on_b;
        float3 albedo = clamp(c, 0.0f, 1.0f);
        float3 e_ms = (albedo * albedo) * (e_avg / (PI_F * (1.0f - e_avg))) / (one - albedo * (1.0f - e_avg));
        f.on_ms = e_ms * (1.0f - (f.on_a * PI_F + f.on_b * Bsdf_oren_nayar_G(f.wo.z)));
    }
    /* sampling weights: each lobe's albedo, estimated at the normal */
    for (int i = 0; i < BSDF_LOBES; ++i) f.q[i] = 0.0f;
    f.q[BSDF_DIFFUSE] = Bsdf_avg(f.diffuse);
    if (f.w_specular > 0.0f)
        f.q[BSDF_SPECULAR] = f.w_specular * Bsdf_avg(Microfacet_fresnel_remap(f.spec_f0, mu, f.spec_eta));
    if (f.w_metal > 0.0f) f.q[BSDF_METAL] = f.w_metal * Bsdf_avg(Bsdf_metal_fresnel(&f, mu));
    if (f.w_glass > 0.0f) {
        float3 gr, gt;
        Bsdf_glass_fresnel(&f, mu, &gr, &gt);
        f.q[BSDF_GLASS] = f.w_glass * Bsdf_avg(gr + gt);
    }
    float total = f.q[0] + f.q[1] + f.q[2] + f.q[3];
    for (int i = 0; i < BSDF_LOBES; ++i) f.q[i] = total > 0.0f ? f.q[i] / total : 0.0f;
    /* a lobe sampling may not choose keeps its chance, which ends the path
     * there (its light comes another way or not at all): a glossy layer over
     * a diffuse base goes on only as often as it reflects */
    if (!(sample & BSDF_SAMPLE_DIFFUSE)) f.q[BSDF_DIFFUSE] = 0.0f;
    if (!(sample & BSDF_SAMPLE_GLOSSY)) f.q[BSDF_SPECULAR] = f.q[BSDF_METAL] = f.q[BSDF_GLASS] = 0.0f;
    return f;
}

/* Whether the material scatters at all by a smooth (evaluable) lobe. */
inline bool Bsdf_has_smooth(const Bsdf *f) {
    return (f->diffuse.x > 0.0f || f->diffuse.y > 0.0f || f->diffuse.z > 0.0f) ||
           (!f->singular && (f->w_specular > 0.0f || f->w_metal > 0.0f || f->w_glass > 0.0f));
}

/* Cycles' bump shadowing term for the light from local direction wi on a
 * lobe of normal n (local) off the smooth surface (a normal map, or the
 * glossy frame raised): nothing where wi and n lie on different sides of
 * the smooth surface (light would leak round to the back), and for the
 * diffuse lobe under a normal map the GGX shadowing of a roughness set by
 * how far the map tilts the normal (Conty Estevez et al. 2019: "Bump Map
 * Correction", on by default), which softens the terminator. */
inline float Bsdf_bump_shadowing(const Bsdf *f, float3 wi, float3 n, bool diffuse) {
    if (!(diffuse ? f->mapped : f->mapped || f->split)) return 1.0f;
    float cos_si = dot(f->smooth, wi), cos_sn = dot(f->smooth, n);
    if (cos_si * cos_sn * dot(n, wi) < 0.0f) return 0.0f;
    if (!diffuse) return 1.0f;
    float cos_i = fabs(cos_si), cos_d = fabs(cos_sn);
    if (cos_d >= 1.0f || cos_i >= 1.0f) return 1.0f;
    if (cos_i < 1e-6f) return 0.0f;
    float alpha2 = clamp(0.125f * (1.0f / (cos_d * cos_d) - 1.0f), 0.0f, 1.0f);
    return 1.0f / (1.0f + Microfacet_lambda(alpha2, cos_i));
}

/* f cos for the local direction wi over the evaluable lobes, split into
 * the diffuse part (*diffuse) and the glossy part (returned; transmission
 * included), and the pdf of sampling wi (Bsdf_sample). A lobe reflects
 * where wi is above both its normal and ng, and transmits where below both. */
inline float3 Bsdf_eval(const Bsdf *f, float3 wi, float3 *diffuse, float *pdf) {
    float3 none = (float3)(0.0f), glossy = none, up = (float3)(0.0f, 0.0f, 1.0f);
    *diffuse = none;
    *pdf = 0.0f;
    bool below = dot(wi, f->ng) < 0.0f;
    if (!below && wi.z > 0.0f) {
        *diffuse = f->diffuse * Bsdf_diffuse_shape(f, wi) * Bsdf_bump_shadowing(f, wi, up, true);
        *pdf += f->q[BSDF_DIFFUSE] * wi.z / PI_F;
    }
    if (f->singular) return none;
    float3 wo = f->gwo, gwi = Bsdf_to_glossy(f, wi), gn = Bsdf_from_glossy(f, up);
    if (below != (gwi.z < 0.0f) || gwi.z == 0.0f) return none;
    if (!below) {
        /* glass is isotropic; metal and specular stretched where anisotropic */
        float lobe_pdf = 0.0f, v = 0.0f, an_pdf = 0.0f, an_v;
        if (!f->aniso || f->w_glass > 0.0f) v = Microfacet_reflect_eval(f->alpha2, wo, gwi, &lobe_pdf);
        an_v = f->aniso ? Microfacet_reflect_eval_aniso(f->ax, f->ay, wo, gwi, &an_pdf) : v;
        an_pdf = f->aniso ? an_pdf : lobe_pdf;
        float cos_h = dot(wo, normalize(wo + gwi));
        if (f->w_specular > 0.0f) {
            glossy += f->w_specular * an_v * f->spec_ms * Microfacet_fresnel_remap(f->spec_f0, cos_h, f->spec_eta);
            *pdf += f->q[BSDF_SPECULAR] * an_pdf;
        }
        if (f->w_metal > 0.0f) {
            glossy += f->w_metal * an_v * f->metal_ms * Bsdf_metal_fresnel(f, cos_h);
            *pdf += f->q[BSDF_METAL] * an_pdf;
        }
        if (f->w_glass > 0.0f) {
            float3 r, t;
            Bsdf_glass_fresnel(f, cos_h, &r, &t);
            glossy += f->w_glass * v * r;
            *pdf += f->q[BSDF_GLASS] * lobe_pdf * Bsdf_reflect_probability(r, t);
        }
        return glossy * Bsdf_bump_shadowing(f, wi, gn, false);
    }
    if (!(f->w_glass > 0.0f) || fabs(f->glass_eta - 1.0f) < 1e-4f) return none;
    float v, lobe_pdf;
    float3 h;
    if (!Microfacet_refract_eval(f->alpha2, f->glass_eta, wo, gwi, &v, &lobe_pdf, &h)) return none;
    float3 r, t;
    Bsdf_glass_fresnel(f, dot(wo, h), &r, &t);
    *pdf += f->q[BSDF_GLASS] * lobe_pdf * (1.0f - Bsdf_reflect_probability(r, t));
    return f->w_glass * v * t * Bsdf_bump_shadowing(f, wi, gn, false);
}

/* Sample a direction: *wi (local), *weight = f cos / pdf over the lobes
 * sampling may choose, *pdf (0 for a singular direction). Returns its
 * BSDF_LABEL_* flags, 0 when the sample is lost (no lobe, a lobe sampling
 * may not choose, below the surface, total internal reflection). */
inline int Bsdf_sample(const Bsdf *f, float u_lobe, float u1, float u2, float u3, float3 *wi, float3 *weight,
                       float *pdf) {
    int lobe = 0;
    float acc = f->q[0];
    while (lobe < BSDF_LOBES - 1 && u_lobe >= acc) acc += f->q[++lobe];
    if (u_lobe >= acc || !(f->q[lobe] > 0.0f)) return 0;
    float3 wo = f->gwo, one = (float3)(1.0f);
    int label;
    if (lobe == BSDF_DIFFUSE) {
        *wi = Sampling_cosine_local(u1, u2);
        label = BSDF_LABEL_DIFFUSE;
    } else {
        bool stretched = f->aniso && lobe != BSDF_GLASS;
        float3 h = f->singular ? (float3)(0.0f, 0.0f, 1.0f)
                               : Microfacet_sample_vndf(wo, stretched ? f->ax : f->rough * f->rough,
                                                        stretched ? f->ay : f->rough * f->rough, u1, u2);
        float cos_h = dot(wo, h);
        if (!(cos_h > 0.0f)) return 0;
        bool refract = false;
        float3 r = one, t = (float3)(0.0f);
        if (lobe == BSDF_GLASS) {
            Bsdf_glass_fresnel(f, cos_h, &r, &t);
            refract = u3 >= Bsdf_reflect_probability(r, t);
        }
        float3 gwi; /* in the glossy frame */
        if (refract) {
            if (!Microfacet_refract(wo, h, f->glass_eta, &gwi)) return 0;
        } else {
            gwi = Bsdf_reflect(-wo, h);
        }
        label = (refract ? BSDF_LABEL_TRANSMIT : 0) | (f->singular ? BSDF_LABEL_SINGULAR : BSDF_LABEL_GLOSSY);
        /* a straight refraction at index 1 is singular at any roughness */
        if (refract && fabs(f->glass_eta - 1.0f) < 1e-4f) {
            label = BSDF_LABEL_TRANSMIT | BSDF_LABEL_SINGULAR;
            gwi = -wo;
        }
        *wi = Bsdf_from_glossy(f, gwi);
        if ((gwi.z < 0.0f) != refract || (dot(*wi, f->ng) < 0.0f) != refract) return 0;
        if (label & BSDF_LABEL_SINGULAR) {
            /* the chosen lobe alone, over its probability */
            float3 value;
            if (lobe == BSDF_GLASS) {
                float p = Bsdf_reflect_probability(r, t);
                value = f->w_glass * (refract ? t / (1.0f - p) : r / p);
            } else if (lobe == BSDF_METAL) {
                value = f->w_metal * f->metal_ms * Bsdf_metal_fresnel(f, cos_h);
            } else {
                value = f->w_specular * f->spec_ms * Microfacet_fresnel_remap(f->spec_f0, cos_h, f->spec_eta);
            }
            *weight = value / f->q[lobe];
            *pdf = 0.0f;
            return label;
        }
    }
    float3 diffuse;
    float3 glossy = Bsdf_eval(f, *wi, &diffuse, pdf);
    if (!(*pdf > 0.0f)) return 0;
    /* the lobes sampling may not choose carry nothing on: their light
     * comes another way (the cache, the cut) or not at all (bounce limits) */
    if (!(f->sample & BSDF_SAMPLE_DIFFUSE)) diffuse = (float3)(0.0f);
    if (!(f->sample & BSDF_SAMPLE_GLOSSY)) glossy = (float3)(0.0f);
    *weight = (glossy + diffuse) / *pdf;
    return label;
}

/* The likeliest direction of a singular BSDF: its most probable lobe, and
 * for glass the likelier of reflection and refraction. False where it
 * scatters nothing. */
inline bool Bsdf_likeliest(const Bsdf *f, float3 *wi) {
    int best = 0;
    for (int i = 1; i < BSDF_LOBES; ++i) best = f->q[i] > f->q[best] ? i : best;
    if (!(f->q[best] > 0.0f)) return false;
    float start = 0.0f;
    for (int i = 0; i < best; ++i) start += f->q[i];
    float3 r, t, weight;
    Bsdf_glass_fresnel(f, f->gwo.z, &r, &t);
    float u3 = best == BSDF_GLASS && Bsdf_reflect_probability(r, t) < 0.5f ? 0.999f : 0.0f;
    float pdf;
    return Bsdf_sample(f, start + 0.5f * f->q[best], 0.5f, 0.5f, u3, wi, &weight, &pdf) != 0;
}

#endif
