// PPF matching (docs/matching.md): Drost et al. 2010 voting over all faces in the world frame,
// with what later work found to help (Vidal et al. 2018: normals from a clean neighbourhood and
// non-smooth points left out, pose clustering with averaging, verification of several
// hypotheses by fit) and, for axisymmetric parts, meridian references and spin-free clustering.
#include "hotgauge/match/match.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <optional>

#include "hotgauge/core/parallel.hpp"
#include "internal.hpp"

namespace hotgauge::match {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

struct Candidate {
    Eigen::Isometry3d T;
    double votes;
};

struct Cluster {
    Eigen::Isometry3d T;  // of the best member
    double votes = 0;
    Eigen::Vector3d axis_sum = Eigen::Vector3d::Zero(), origin_sum = Eigen::Vector3d::Zero();
    Eigen::Quaterniond q_sum = Eigen::Quaterniond(0, 0, 0, 0);
};

Eigen::Isometry3d from_ref_frames(const Eigen::Matrix<float, 3, 4>& Ts,
                                  const Eigen::Matrix<float, 3, 4>& Tm, float alpha) {
    Eigen::Isometry3d S = Eigen::Isometry3d::Identity(), M = Eigen::Isometry3d::Identity();
    S.matrix().topRows<3>() = Ts.cast<double>();
    M.matrix().topRows<3>() = Tm.cast<double>();
    return S.inverse() * Eigen::AngleAxisd(alpha, Eigen::Vector3d::UnitX()) * M;
}

// Every stride-th scene sample is a reference point: at most max_refs, evenly spread.
std::size_t reference_stride(std::size_t n, int max_refs) {
    const auto m = static_cast<std::size_t>(std::max(1, max_refs));
    return std::max<std::size_t>(1, (n + m - 1) / m);
}

// Hough voting: per scene reference point, an accumulator over (model reference × α).
std::vector<Candidate> vote(const Model& model, const detail::Samples& scene, int max_refs,
                            int threads) {
    const int A = model.config.alpha_bins;
    const float bin = 2.0f * std::numbers::pi_v<float> / static_cast<float>(A);
    const float inv_bin = 1.0f / bin;
    const auto n = scene.points.size();
    const std::size_t stride = reference_stride(n, max_refs);
    const float max_d2 = static_cast<float>(model.diameter_mm * model.diameter_mm);
    // Accumulator rows of 2A cells per model reference: a vote for α = α_m − α_s lands in cell
    // A + α_m − α_s (never wraps), and cells b and b + A are folded afterwards. Each entry's cell
    // A + α_m is precomputed, so the inner loop is one load, one add, one increment.
    const std::size_t row = 2 * static_cast<std::size_t>(A);
    std::vector<std::uint32_t> cell(model.entries.size());
    for (std::size_t e = 0; e < cell.size(); ++e) {
        const int am = std::clamp(
            static_cast<int>((model.entries[e].alpha + std::numbers::pi_v<float>)*inv_bin), 0,
            A - 1);
        cell[e] = static_cast<std::uint32_t>(model.entries[e].ref * row +
                                             static_cast<std::size_t>(A + am));
    }
    std::vector<Eigen::Matrix<float, 3, 4>> Tm(model.refs.size());
    for (std::size_t r = 0; r < model.refs.size(); ++r)
        Tm[r] = to_ref_frame(model.points[model.refs[r]], model.normals[model.refs[r]]);
    // Scene reference points vote independently: they are spread over the cores, each worker
    // with its own accumulator, and each reference's candidates are kept apart and concatenated
    // in reference order, so the result is the same as from one thread.
    const std::size_t n_refs = (n + stride - 1) / stride;
    std::vector<std::vector<Candidate>> found(n_refs);
    struct Scratch {
        std::vector<std::uint32_t> acc, folded;
    };
    std::vector<Scratch> scratch(core::worker_count(threads));
    core::parallel_for(n_refs, threads, [&](std::size_t ref, unsigned worker) {
        auto& acc = scratch[worker].acc;
        auto& folded = scratch[worker].folded;
        acc.assign(model.refs.size() * row, 0);
        folded.resize(model.refs.size() * static_cast<std::size_t>(A));
        const std::size_t s = ref * stride;
        const Eigen::Vector3f& ps = scene.points[s];
        const Eigen::Vector3f& ns = scene.normals[s];
        const auto Ts = to_ref_frame(ps, ns);
        for (std::size_t j = 0; j < n; ++j) {
            if (j == s || (scene.points[j] - ps).squaredNorm() > max_d2) continue;
            const std::uint32_t key = model.key(ps, ns, scene.points[j], scene.normals[j]);
            if (key == kNoKey) continue;
            const std::uint32_t e0 = model.key_begin[key], e1 = model.key_begin[key + 1];
            if (e0 == e1) continue;
            const Eigen::Vector3f q = Ts * scene.points[j].homogeneous();
            const int as = std::clamp(
                static_cast<int>((std::atan2(-q.z(), q.y()) + std::numbers::pi_v<float>)*inv_bin),
                0, A - 1);
            const auto off = static_cast<std::uint32_t>(as);  // < A <= every cell's offset
            std::uint32_t* a = acc.data();
            for (std::uint32_t e = e0; e < e1; ++e) ++a[cell[e] - off];
        }
        for (std::size_t r = 0; r < model.refs.size(); ++r)
            for (std::size_t b = 0; b < static_cast<std::size_t>(A); ++b)
                folded[r * static_cast<std::size_t>(A) + b] =
                    acc[r * row + b] + acc[r * row + b + static_cast<std::size_t>(A)];
        // The best cell of this reference point, and a second one when nearly as good (the
        // flipped part seen from one side scores close).
        std::size_t best = 0, second = 0;
        for (std::size_t c = 1; c < folded.size(); ++c)
            if (folded[c] > folded[best]) best = c;
        for (std::size_t c = 0; c < folded.size(); ++c)
            if (c != best && folded[c] > folded[second]) second = c;
        for (std::size_t c : {best, second}) {
            if (folded[c] < 3 ||
                (c == second && (second == best || folded[c] < folded[best] * 0.8)))
                continue;
            const auto r = c / static_cast<std::size_t>(A);
            const float alpha = static_cast<float>(c % static_cast<std::size_t>(A)) * bin;
            found[ref].push_back(
                {from_ref_frames(Ts, Tm[r], alpha), static_cast<double>(folded[c])});
        }
    });
    std::vector<Candidate> out;
    for (auto& f : found) out.insert(out.end(), f.begin(), f.end());
    return out;
}

std::vector<Cluster> cluster(const Model& model, std::vector<Candidate> cands, double angle_deg,
                             double dist_mm) {
    std::sort(cands.begin(), cands.end(),
              [](const Candidate& a, const Candidate& b) { return a.votes > b.votes; });
    const double cos_max = std::cos(angle_deg * std::numbers::pi / 180.0);
    std::vector<Cluster> clusters;
    for (const auto& c : cands) {
        const Eigen::Vector3d axis = c.T.linear().col(2), origin = c.T.translation();
        const Eigen::Quaterniond q(c.T.linear());
        Cluster* home = nullptr;
        for (auto& k : clusters) {
            if ((k.T.translation() - origin).norm() > dist_mm) continue;
            const bool close = model.axisymmetric
                                   ? k.T.linear().col(2).dot(axis) > cos_max
                                   : std::abs(Eigen::Quaterniond(k.T.linear()).dot(q)) >
                                         std::cos(0.5 * angle_deg * std::numbers::pi / 180.0);
            if (close) {
                home = &k;
                break;
            }
        }
        if (!home) {
            clusters.push_back({c.T});
            home = &clusters.back();
        }
        home->votes += c.votes;
        home->axis_sum += c.votes * axis;
        home->origin_sum += c.votes * origin;
        const Eigen::Quaterniond q0(home->T.linear());
        const double sgn = q0.dot(q) < 0 ? -1.0 : 1.0;
        home->q_sum.coeffs() += sgn * c.votes * q.coeffs();
    }
    // Each cluster's pose: the vote-weighted mean of its members.
    for (auto& k : clusters) {
        k.T.translation() = k.origin_sum / k.votes;
        if (model.axisymmetric) {
            const Eigen::Vector3d a = k.axis_sum.normalized();
            k.T.linear() =
                Eigen::Quaterniond::FromTwoVectors(k.T.linear().col(2), a).toRotationMatrix() *
                k.T.linear();
        } else {
            k.T.linear() = k.q_sum.normalized().toRotationMatrix();
        }
    }
    std::sort(clusters.begin(), clusters.end(),
              [](const Cluster& a, const Cluster& b) { return a.votes > b.votes; });
    return clusters;
}

}  // namespace

Eigen::Isometry3d canonical_spin(const Eigen::Isometry3d& T) {
    const Eigen::Vector3d a = T.linear().col(2);
    Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
    if (a.z() < -1.0 + 1e-12)
        out.linear() =
            Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX()).toRotationMatrix();
    else
        out.linear() =
            Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), a).toRotationMatrix();
    out.translation() = T.translation();
    return out;
}

AxisError axis_error(const Eigen::Isometry3d& T_true, const Eigen::Isometry3d& T_est) {
    const Eigen::Vector3d a_t = T_true.linear().col(2), a_e = T_est.linear().col(2);
    AxisError e;
    e.angle_deg = std::atan2(a_t.cross(a_e).norm(), a_t.dot(a_e)) * 180.0 / std::numbers::pi;
    const Eigen::Vector3d d = T_true.translation() - T_est.translation();
    e.axial_mm = d.dot(a_e);
    e.radial_mm = (d - e.axial_mm * a_e).norm();
    e.axial_mm = std::abs(e.axial_mm);
    return e;
}

MatchResult match(const Model& model, const core::Recording& rec, const core::FaceDisplacements& u,
                  const MatchConfig& cfg) {
    MatchResult res;
    const auto t0 = Clock::now();
    const double sampling =
        cfg.scene_sampling_mm > 0 ? cfg.scene_sampling_mm : model.config.sampling_mm;
    // The voting samples, the dense ICP grid and the model surface are independent: built
    // concurrently (the samples take the longest; the other worker does the rest).
    detail::Samples scene;
    std::vector<Eigen::Vector3f> dense;
    std::optional<detail::Surface> surface_built;
    core::parallel_for(3, cfg.threads, [&](std::size_t job, unsigned) {
        if (job == 0)
            scene = detail::voting_samples(rec, u, sampling, cfg.normal_radius_mm);
        else if (job == 1)
            dense = detail::grid_points(rec, u, cfg.icp_grid_mm);
        else
            surface_built.emplace(model);
    });
    const detail::Surface& surface = *surface_built;
    const double part_extent = 2.0 * surface.half_size();
    if (cfg.remove_background_plane) {
        // Larger than any plane of the part: for an axisymmetric part its largest diameter.
        const double min_extent =
            1.2 * (model.axisymmetric ? 2.0 * surface.max_radius() : part_extent);
        if (auto pl = detail::background_plane(scene, cfg.background_band_mm, min_extent)) {
            const auto band = static_cast<float>(cfg.background_band_mm);
            detail::Samples kept;
            for (std::size_t i = 0; i < scene.points.size(); ++i)
                if (std::abs(pl->distance(scene.points[i])) >= band) {
                    kept.points.push_back(scene.points[i]);
                    kept.normals.push_back(scene.normals[i]);
                }
            res.background_removed =
                static_cast<std::int64_t>(scene.points.size() - kept.points.size());
            scene = std::move(kept);
            std::erase_if(
                dense, [&](const Eigen::Vector3f& p) { return std::abs(pl->distance(p)) < band; });
        }
    }
    res.scene_points = static_cast<std::int64_t>(scene.points.size());
    res.stage_ms.emplace_back("prepare", ms_since(t0));
    if (scene.points.size() < 20) {
        res.reason = "part not found: " + std::to_string(scene.points.size()) +
                     " usable scene samples (empty or tiny scene)";
        return res;
    }

    const auto t1 = Clock::now();
    auto cands = vote(model, scene, cfg.max_reference_points, cfg.threads);
    const std::size_t stride = reference_stride(scene.points.size(), cfg.max_reference_points);
    res.reference_points = static_cast<std::int64_t>((scene.points.size() + stride - 1) / stride);
    const double dist = cfg.cluster_distance_mm > 0 ? cfg.cluster_distance_mm : 2.0 * sampling;
    auto clusters = cluster(model, std::move(cands), cfg.cluster_angle_deg, dist);
    res.stage_ms.emplace_back("vote", ms_since(t1));
    if (clusters.empty()) {
        res.reason = "part not found: no pose received votes";
        return res;
    }

    // Verification: coarse ICP of the best clusters on the voting samples; the one the most
    // scene samples support wins (the flipped hub seen from one side loses here).
    const auto t2 = Clock::now();
    const double scale0 = cfg.scale.value_or(1.0);
    const bool est_scale = !cfg.scale.has_value();
    detail::IcpOptions coarse;
    coarse.gates_mm = {3.0 * sampling, 1.5 * sampling, 0.5 * sampling};
    coarse.iterations_per_stage = 4;
    coarse.max_iterations = 12;
    coarse.stop_mm = 0.01;
    struct Hyp {
        detail::IcpResult icp;
        detail::Support sup;
        double votes;
    };
    std::optional<Hyp> best;
    const int n_hyp = std::min<int>(cfg.max_hypotheses, static_cast<int>(clusters.size()));
    for (int h = 0; h < n_hyp; ++h) {
        auto r = detail::icp(surface, model, scene.points, clusters[h].T, scale0, coarse);
        const auto sup = detail::support(surface, scene.points, r.T_world_part, r.scale,
                                         0.5 * sampling, 0.5 * sampling);
        if (!best || sup.inliers > best->sup.inliers) best = Hyp{r, sup, clusters[h].votes};
    }
    res.hypotheses = n_hyp;
    res.votes = best->votes;
    res.stage_ms.emplace_back("verify", ms_since(t2));

    // Fine ICP on the dense grid near the part.
    const auto t3 = Clock::now();
    {
        const Eigen::Isometry3f T_pw = best->icp.T_world_part.inverse().cast<float>();
        const auto s = static_cast<float>(best->icp.scale);
        std::erase_if(dense, [&](const Eigen::Vector3f& p) {
            return !surface.inside_region(T_pw * p, s, static_cast<float>(sampling));
        });
    }
    detail::IcpOptions fine;
    fine.gates_mm = {sampling, 1.0, 0.5};
    fine.iterations_per_stage = 10;
    fine.max_iterations = cfg.icp_max_iterations;
    fine.stop_mm = cfg.icp_stop_mm;
    fine.estimate_scale = est_scale;
    fine.free_radii = true;
    auto fin = detail::icp(surface, model, dense, best->icp.T_world_part, best->icp.scale, fine);
    res.stage_ms.emplace_back("icp", ms_since(t3));
    const double band = cfg.score_band_mm > 0 ? cfg.score_band_mm : cfg.inlier_band_mm;
    const auto sup = detail::support(surface, dense, fin.T_world_part, fin.scale, band, band);
    res.T_world_part = model.axisymmetric ? canonical_spin(fin.T_world_part) : fin.T_world_part;
    res.scale = fin.scale;
    res.scale_estimated = est_scale;
    res.rms_mm = fin.rms_mm;
    res.iterations = fin.iterations;
    res.inliers = sup.inliers;
    res.score = sup.fraction();
    if (sup.inliers < cfg.min_inliers) {
        res.reason = "part not found: best score " + std::to_string(res.score) + " with " +
                     std::to_string(sup.inliers) + " supporting points (need " +
                     std::to_string(cfg.min_inliers) + ")";
        return res;
    }
    if (res.score < cfg.min_score) {
        res.reason = "part not found: best score " + std::to_string(res.score) + " < " +
                     std::to_string(cfg.min_score);
        return res;
    }
    res.found = true;
    return res;
}

}  // namespace hotgauge::match
